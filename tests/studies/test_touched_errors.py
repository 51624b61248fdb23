"""experiments/touched_errors.py: touched-cell errors by distance to the benchmark's walls, counted on a map
whose errors are placed by hand, and its JSON and figure."""

from __future__ import annotations

import json

import numpy as np
import pytest

from tests._scripts import load_experiment

te = load_experiment("touched_errors", "touched_errors.py")


@pytest.fixture
def folder(tmp_path):
    """A 12 x 12 benchmark with a wall two cells thick (columns 8-9), every cell left of column 10 touched.
    Map ``thick`` calls the wall and column 7 (one cell in front of its face) occupied, and the single cell
    (5, 1), six cells from the wall; map ``thin`` calls only column 8 (misses column 9, depth 2)."""
    truth = np.zeros((12, 12), bool)
    truth[:, 8:10] = True
    touched = np.zeros((12, 12), bool)
    touched[:, :10] = True
    (tmp_path / "datasets").mkdir()
    np.savez(tmp_path / "datasets" / "d.eval.npz", truth=truth, touched=touched, mapped=touched)
    maps = tmp_path / "maps" / "d"
    maps.mkdir(parents=True)
    thick = np.zeros((12, 12))
    thick[:, 7:10] = 0.9
    thick[5, 1] = 0.9
    thin = np.zeros((12, 12))
    thin[:, 8] = 0.9
    # the touched best F1 the experiment would record: thick 24 TP, 13 FP; thin 12 TP, 12 FN
    for name, q, f1 in (("thick", thick, 48 / 61), ("thin", thin, 24 / 36)):
        np.savez(maps / f"{name}.npz", marginals=q)
        (maps / f"{name}.json").write_text(json.dumps({"touched": {"threshold": 0.5, "best_f1": f1}}))
    return tmp_path


def test_errors_are_counted_by_distance_and_depth(folder):
    thick = te.touched_errors(folder, "d", "thick")
    assert thick["fp_binned"] == {"1": 12, "2-3": 0, "4+": 1}
    assert thick["fp_by_distance_1_to_6plus"] == [12, 0, 0, 0, 0, 1]
    assert (thick["true_positives"], thick["false_negatives"], thick["false_positives"]) == (24, 0, 13)
    assert thick["walls_by_depth"] == {
        1: {"cells": 12, "called_occupied": 1.0},
        2: {"cells": 12, "called_occupied": 1.0},
    }
    thin = te.touched_errors(folder, "d", "thin")
    assert thin["walls_by_depth"][2]["called_occupied"] == 0.0 and thin["walls_by_depth"][1]["called_occupied"] == 1.0
    assert (thin["true_positives"], thin["false_negatives"], thin["false_positives"]) == (12, 12, 0)


def test_counts_that_disagree_with_the_experiments_f1_are_refused(folder):
    """A map file whose recorded touched F1 is not what its cells give (another truth, another threshold)."""
    path = folder / "maps" / "d" / "thin.json"
    path.write_text(json.dumps({"touched": {"threshold": 0.5, "best_f1": 0.7}}))
    with pytest.raises(SystemExit, match=r"give F1 0\.666667 at threshold 0\.5, the experiment recorded 0\.700000"):
        te.touched_errors(folder, "d", "thin")


def test_main_writes_json_and_figure_and_refuses_missing_maps(folder, tmp_path):
    out = tmp_path / "report"
    res = te.main([str(folder), "thick", "thin", "--out", str(out)])
    assert json.loads((out / "touched_errors.json").read_text())["datasets"]["d"]["thick"]["fp_binned"]["1"] == 12
    assert res["algorithms"] == ["thick", "thin"]
    assert (out / "touched_errors.png").read_bytes()[:4] == b"\x89PNG"
    with pytest.raises(SystemExit, match="no map of algorithm 'other'"):
        te.main([str(folder), "other"])
    (tmp_path / "empty" / "datasets").mkdir(parents=True)
    with pytest.raises(SystemExit, match="no scored dataset"):
        te.main([str(tmp_path / "empty"), "thick"])
    with pytest.raises(SystemExit, match="not an experiment folder"):
        te.main([str(tmp_path / "nowhere"), "thick"])
