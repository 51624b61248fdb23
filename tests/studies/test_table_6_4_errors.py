"""ogm_ppl.studies.table_6_4_errors: pooled best F1 with its errors split into touched and never-touched
cells, the two oracle maps, and clear errors for missing or mismatched files; experiments/table_6_4_errors.py
prints and writes it."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from ogm_ppl.metrics import precision_recall
from ogm_ppl.studies.table_6_4_errors import ORACLES, error_split, error_split_text
from tests._experiments import run_script


def _dataset(out: Path, name: str, truth, touched, maps: dict) -> None:
    (out / "datasets").mkdir(parents=True, exist_ok=True)
    np.savez(out / "datasets" / f"{name}.eval.npz", truth=truth, touched=touched, mapped=touched)
    d = out / "maps" / name
    d.mkdir(parents=True)
    for alg, q in maps.items():
        np.savez(d / f"{alg}.npz", marginals=q, format_version=1)


@pytest.fixture
def run(tmp_path):
    rng = np.random.default_rng(0)
    data = []
    for i in range(2):
        truth = rng.random((9, 9)) < 0.4
        touched = rng.random((9, 9)) < 0.6
        maps = {"a": rng.random((9, 9)), "b": np.clip(truth + rng.normal(0, 0.3, (9, 9)), 0, 1)}
        _dataset(tmp_path, f"d{i}", truth, touched, maps)
        data.append((truth.ravel(), touched.ravel(), {k: v.ravel() for k, v in maps.items()}))
    return tmp_path, data


def test_pooled_scores_and_the_split_equal_a_direct_count(run):
    out, data = run
    res = error_split(out)
    truth = np.concatenate([t for t, _, _ in data])
    touched = np.concatenate([m for _, m, _ in data])
    assert res["datasets"] == 2 and res["cells"]["touched"] == touched.sum()
    for alg in ("a", "b"):
        q = np.concatenate([maps[alg] for _, _, maps in data])
        c = precision_recall(q, truth)
        i = int(np.argmax(c.f1))
        s = res["algorithms"][alg]
        assert s["best_f1"] == pytest.approx(c.f1[i], abs=1e-12) and s["threshold"] == pytest.approx(c.thresholds[i])
        called = q > c.thresholds[i]
        assert s["fp_touched"] == (called & ~truth & touched).sum()
        assert s["fp_untouched"] == (called & ~truth & ~touched).sum()
        assert s["fn_touched"] == (~called & truth & touched).sum()
        assert s["fn_untouched"] == (~called & truth & ~touched).sum()
        assert s["fp_touched"] + s["fp_untouched"] == c.fp[i] and s["fn_touched"] + s["fn_untouched"] == c.fn[i]
    for name, fill in zip(ORACLES, (True, False)):
        q = np.where(touched, truth, fill).astype(float)
        assert res["oracles"][name] == pytest.approx(precision_recall(q, truth).f1.max(), abs=1e-12)


def test_the_script_prints_and_writes_json(run, tmp_path):
    out, _ = run
    r = run_script("table_6_4_errors.py", out, "--json", tmp_path / "e.json")
    assert r.returncode == 0, r.stderr
    res = error_split(out)
    assert r.stdout.startswith(error_split_text(res)) and "touched truth, rest occupied" in r.stdout
    assert json.loads((tmp_path / "e.json").read_text()) == res
    bad = run_script("table_6_4_errors.py", tmp_path / "nowhere")
    assert bad.returncode == 1 and "no maps folder" in bad.stderr


def test_bad_folders_are_refused(tmp_path):
    with pytest.raises(FileNotFoundError, match="no maps folder"):
        error_split(tmp_path)
    (tmp_path / "maps" / "d0").mkdir(parents=True)
    with pytest.raises(FileNotFoundError, match=r"d0\.eval\.npz: missing"):
        error_split(tmp_path)
    (tmp_path / "datasets").mkdir()
    np.savez(tmp_path / "datasets" / "d0.eval.npz", truth=np.zeros(4, bool), touched=np.zeros(4, bool))
    np.savez(tmp_path / "maps" / "d0" / "x.npz", marginals=np.zeros(3))
    with pytest.raises(ValueError, match=r"x\.npz: 3 cells, the dataset's truth has 4"):
        error_split(tmp_path)
    np.savez(tmp_path / "maps" / "d0" / "x.npz", other=np.zeros(4))
    with pytest.raises(ValueError, match="no 'marginals' array"):
        error_split(tmp_path)


def test_an_algorithm_missing_from_a_dataset_is_refused_unless_left_out(run):
    out, _ = run
    (out / "maps" / "d1" / "b.npz").unlink()
    with pytest.raises(FileNotFoundError, match=r"d1: no map of b"):
        error_split(out)
    assert list(error_split(out, algorithms=["a"])["algorithms"]) == ["a"]
