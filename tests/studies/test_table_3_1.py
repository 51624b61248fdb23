"""ogm_ppl.studies.table_3_1: the Gibbs row's KL is of Monte Carlo size and far below every other row's, settings
out of range are refused naming them, and experiments/table_3_1.py writes the table where it is told."""

import json

import pytest

from ogm_ppl.studies.errors import StudyOptionError
from ogm_ppl.studies.table_3_1 import THESIS, Table31Settings, datasets, table_3_1
from tests._experiments import run_script


def test_table_3_1_setup_subsample():
    """Table 3.1's Gibbs entry on a subsample: the mean summed KL is of Monte Carlo size. With n nearly
    independent sweeps each uncertain cell adds about 1 / (2n); we allow an autocorrelation time of 2."""
    n, K = 20_000, 30
    rows = table_3_1(Table31Settings(datasets=12, gibbs_sweeps=n, cells=K), progress=False)["rows"]
    gibbs = rows["Gibbs"]["mean"]
    assert 0 < gibbs < 2 * K / (2 * n)
    # Gibbs beats every patch method and traditional OGM by orders of magnitude
    assert all(v["mean"] > 10 * gibbs for k, v in rows.items() if k != "Gibbs")
    assert {k: v["thesis"] for k, v in rows.items() if v["thesis"] is not None} == THESIS


def test_the_datasets_hold_one_to_eight_readings_on_the_grid():
    zs = list(datasets(200, 25, seed=3))
    assert {len(z) for z in zs} == set(range(1, 9))
    assert all(z.min() >= 0 and z.max() <= 25 and (z == z.round()).all() for z in zs)
    assert all((a == b).all() for a, b in zip(zs, datasets(200, 25, seed=3)))


@pytest.mark.parametrize(
    "change, option", [({"datasets": 0}, "datasets"), ({"cells": 19}, "cells"), ({"gibbs_sweeps": -1}, "gibbs_sweeps")]
)
def test_settings_out_of_range_are_refused(change, option, tmp_path):
    with pytest.raises(StudyOptionError, match=f"^{option}: must be") as e:
        table_3_1(Table31Settings(**change), tmp_path, progress=False)
    assert e.value.option == option and not any(tmp_path.iterdir())


def test_the_script_writes_the_table_into_its_folder(tmp_path):
    r = run_script("table_3_1.py", "--datasets", 2, "--gibbs-sweeps", 20, "--out", tmp_path)
    assert r.returncode == 0, r.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["table_3_1.json", "table_3_1.md"]
    res = json.loads((tmp_path / "table_3_1.json").read_text())
    assert (res["datasets"], res["gibbs_sweeps"], res["cells"]) == (2, 20, 30) and len(res["rows"]) == 12
    assert "| offline, overlap L=5 |" in r.stdout and r.stdout.strip() == (tmp_path / "table_3_1.md").read_text()
    bad = run_script("table_3_1.py", "--datasets", 0, "--out", tmp_path / "x")
    assert bad.returncode == 2 and "error: datasets: must be" in bad.stderr and not (tmp_path / "x").exists()
