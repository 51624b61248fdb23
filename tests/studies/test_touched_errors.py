"""ogm_ppl.studies.touched_errors: touched-cell errors by distance to the benchmark's walls, counted on a map
whose errors are placed by hand, and its JSON and figure; experiments/touched_errors.py runs it."""

from __future__ import annotations

import json

import numpy as np
import pytest

from ogm_ppl.studies.errors import StudyInputError
from ogm_ppl.studies.touched_errors import count_touched_errors, touched_errors
from tests._experiments import run_script


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
    thick = count_touched_errors(folder, "d", "thick")
    assert thick["fp_binned"] == {"1": 12, "2-3": 0, "4+": 1}
    assert thick["fp_by_distance_1_to_6plus"] == [12, 0, 0, 0, 0, 1]
    assert (thick["true_positives"], thick["false_negatives"], thick["false_positives"]) == (24, 0, 13)
    assert thick["walls_by_depth"] == {
        1: {"cells": 12, "called_occupied": 1.0},
        2: {"cells": 12, "called_occupied": 1.0},
    }
    thin = count_touched_errors(folder, "d", "thin")
    assert thin["walls_by_depth"][2]["called_occupied"] == 0.0 and thin["walls_by_depth"][1]["called_occupied"] == 1.0
    assert (thin["true_positives"], thin["false_negatives"], thin["false_positives"]) == (12, 12, 0)


def test_counts_that_disagree_with_the_experiments_f1_are_refused(folder):
    """A map file whose recorded touched F1 is not what its cells give (another truth, another threshold)."""
    path = folder / "maps" / "d" / "thin.json"
    path.write_text(json.dumps({"touched": {"threshold": 0.5, "best_f1": 0.7}}))
    match = r"give F1 0\.666667 at threshold 0\.5, the experiment recorded 0\.700000"
    with pytest.raises(StudyInputError, match=match):
        count_touched_errors(folder, "d", "thin")


def test_the_study_writes_json_and_figure_and_refuses_missing_maps(folder, tmp_path):
    out = tmp_path / "report"
    res = touched_errors(folder, ["thick", "thin"], out_dir=out)
    assert json.loads((out / "touched_errors.json").read_text())["datasets"]["d"]["thick"]["fp_binned"]["1"] == 12
    assert res["algorithms"] == ["thick", "thin"] and list(res["datasets"]) == ["d"]
    assert (out / "touched_errors.png").read_bytes()[:4] == b"\x89PNG"
    assert sorted(p.name for p in out.iterdir()) == ["touched_errors.json", "touched_errors.png"]
    assert touched_errors(folder, ["thin"], datasets=["d"]) == {
        "experiment": str(folder),
        "algorithms": ["thin"],
        "datasets": {"d": {"thin": count_touched_errors(folder, "d", "thin")}},
    }
    with pytest.raises(StudyInputError, match="no map of algorithm 'other'"):
        touched_errors(folder, ["other"])
    (tmp_path / "empty" / "datasets").mkdir(parents=True)
    with pytest.raises(StudyInputError, match="no scored dataset"):
        touched_errors(tmp_path / "empty", ["thick"])
    with pytest.raises(StudyInputError, match="not an experiment folder"):
        touched_errors(tmp_path / "nowhere", ["thick"])


def test_the_script_prints_and_writes_the_counts(folder, tmp_path):
    out = tmp_path / "report"
    r = run_script("touched_errors.py", folder, "thick", "thin", "--out", out)
    assert r.returncode == 0, r.stderr
    assert r.stdout.splitlines()[0] == 'd thick {"touched_best_f1": 0.7868852459016393, "false_negatives": 0, ' + (
        '"fp_binned": {"1": 12, "2-3": 0, "4+": 1}}'
    )
    expected = json.loads(json.dumps(touched_errors(folder, ["thick", "thin"])))  # depths as JSON keys
    assert json.loads((out / "touched_errors.json").read_text()) == expected
    bad = run_script("touched_errors.py", folder, "other")
    assert bad.returncode == 1 and bad.stderr.strip().endswith("no map of algorithm 'other' on dataset 'd'")
