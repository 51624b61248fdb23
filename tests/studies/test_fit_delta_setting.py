"""ogm_ppl.studies.fit_delta_setting: the fitted and the shipped term scored on the same held-out data of the
setting, the fitted term written only into the folder given; experiments/fit_delta_setting.py has its options."""

import pytest
import torch

from ogm_ppl.datasets import wall_datasets
from ogm_ppl.inference.variational.delta_fit import cross_entropy_loss
from ogm_ppl.learn import FitOptionError
from ogm_ppl.models import delta_by_name
from ogm_ppl.studies.fit_delta_setting import delta_setting_heldout, delta_setting_lines
from tests._experiments import run_script


def test_the_fit_and_the_shipped_term_on_the_same_heldout_data(tmp_path):
    doc = delta_setting_heldout(1.0, 20, num=20, heldout=10, names=["p21"], out_dir=tmp_path, compare_full=True)
    assert (doc["wall"], doc["num"], doc["heldout"]) == (16, 20, 10) and list(doc["terms"]) == ["p21"]
    t = doc["terms"]["p21"]
    held = wall_datasets(num=10, F=20, wall=16, sigma=1.0, seed=1)
    with torch.no_grad():
        assert t["heldout_ce_shipped"] == pytest.approx(float(cross_entropy_loss(delta_by_name("p21"), held)))
    assert t["heldout_ce_fit"] < t["heldout_ce_shipped"]  # fitted for this setting, the shipped one is not
    assert [p.suffix for p in tmp_path.iterdir()] == [".json"]
    assert [(f["name"], f["reduce"]) for f in doc["full"]] == [("p21", True), ("p21", False)]
    assert doc["full"][0]["train_ce"] == pytest.approx(doc["full"][1]["train_ce"], rel=1e-9)
    lines = delta_setting_lines(doc)
    assert lines[0].startswith("setting: sigma 1 cells, F 20, wall 16") and lines[3].startswith("| p21 |")
    with pytest.raises(FitOptionError):
        delta_setting_heldout(-1.0, 20, num=20, heldout=10, names=["p21"])


def test_the_script_has_its_options():
    r = run_script("fit_delta_setting.py", "--help")
    assert r.returncode == 0 and "--compare-full" in r.stdout and "--names" in r.stdout, r.stderr
