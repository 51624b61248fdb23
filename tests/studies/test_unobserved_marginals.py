"""ogm_ppl.studies.unobserved_marginals: the mean marginal over the cells traditional OGM leaves at 0.5, and
clear errors for a missing folder or baseline and for a map of another size; experiments/unobserved_marginals.py
prints it."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from ogm_ppl.studies.unobserved_marginals import unobserved_means
from tests._experiments import run_script


def _write(d: Path, name: str, q) -> None:
    d.mkdir(parents=True, exist_ok=True)
    np.savez(d / f"{name}.npz", marginals=np.asarray(q, dtype=np.float64), format_version=1)


def test_means_over_never_observed_cells(tmp_path):
    _write(tmp_path / "maps" / "a", "ogm", [0.5, 0.9, 0.5, 0.1])
    _write(tmp_path / "maps" / "a", "gibbs", [0.2, 1.0, 0.6, 0.0])
    _write(tmp_path / "maps" / "b", "ogm", [0.5, 0.5, 0.7, 0.5])
    _write(tmp_path / "maps" / "b", "gibbs", [1.0, 0.0, 0.3, 0.5])
    res = unobserved_means(tmp_path)
    assert res["gibbs"] == {"a": pytest.approx(0.4), "b": pytest.approx(0.5)}
    assert res["ogm"] == {"a": 0.5, "b": 0.5}
    r = run_script("unobserved_marginals.py", tmp_path)
    assert r.returncode == 0 and "gibbs: mean 0.450, range 0.40-0.50 over 2 datasets" in r.stdout, r.stderr
    r = run_script("unobserved_marginals.py", tmp_path, "--json")
    assert json.loads(r.stdout) == res


def test_bad_folders_are_refused(tmp_path):
    with pytest.raises(FileNotFoundError, match="no maps folder"):
        unobserved_means(tmp_path)
    _write(tmp_path / "maps" / "a", "gibbs", [0.2])
    with pytest.raises(FileNotFoundError, match="baseline map is missing"):
        unobserved_means(tmp_path)
    _write(tmp_path / "maps" / "a", "ogm", [0.5, 0.5])
    with pytest.raises(ValueError, match="1 cells, the baseline has 2"):
        unobserved_means(tmp_path)
