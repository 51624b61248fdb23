"""experiments/prior_occupancy.py: a prior's own occupied share on a window with no readings. Under the learned
independent prior every recorded state is an exact draw (each sweep redraws every cell from ``lambda``), so the
mean share must lie within 4 standard errors of the corpus's ``lambda``."""

import json
import math
import sys

import pytest

from ogm_ppl.priors.named import prior_by_name
from tests._scripts import load_experiment


@pytest.fixture(scope="module")
def po():
    yield load_experiment("prior_occupancy_experiment", "prior_occupancy.py")
    sys.modules.pop("prior_occupancy_experiment", None)


def test_the_independent_prior_fills_its_lambda(po, tmp_path):
    argv = ["--priors", "independent", "--train", "dungeon", "--window", "20", "--sweeps", "40", "--every", "2"]
    doc = po.main([*argv, "--out", str(tmp_path)])
    (row,) = doc["rows"]
    assert row["prior"] == "independent:dungeon" and [len(t) for t in row["traces"]] == [20, 20, 20]
    lam = row["corpus_share"]
    _, counted = po.empty_model(prior_by_name("independent:dungeon", (20, 20)), 20)
    K, n = int(counted.sum()), 3 * 10  # counted cells; recorded states in the chains' second halves
    assert 0 < K < 400
    assert abs(row["share"] - lam) < 4 * math.sqrt(lam * (1 - lam) / (K * n))
    assert json.loads((tmp_path / "prior_occupancy.json").read_text())["rows"][0]["share"] == row["share"]


def test_a_tile_prior_runs_from_every_start(po, tmp_path):
    argv = ["--priors", "border_bo", "--train", "houseexpo", "--window", "12", "--sweeps", "4", "--every", "2"]
    (row,) = po.main([*argv, "--out", str(tmp_path)])["rows"]
    assert row["patch"] == [3, 3] and len(row["chain_shares"]) == 3
    assert row["traces"][1][0] > row["traces"][0][0]  # the all-occupied start is still fuller after 2 sweeps


@pytest.mark.parametrize(
    "argv, match",
    [
        (["--window", "2"], "--window must be at least 4"),
        (["--sweeps", "10", "--every", "6"], "--sweeps at least 2 x --every"),
        (["--priors", "border_bo:dungeon"], "--priors takes kinds"),
    ],
)
def test_bad_settings_are_refused(po, tmp_path, argv, match):
    with pytest.raises(SystemExit, match=match):
        po.main([*argv, "--out", str(tmp_path)])


def test_the_fitted_bias_of_the_independent_prior_is_near_zero(po, tmp_path):
    """The learned independent prior already fills its corpus's share, so the fitted bias is 0 up to the bisection's
    resolution (4 / 2^8 = 0.016) and the noise of 20 recorded states of ~390 cells (a share's standard error of
    0.0055, 0.023 in ``h`` at a slope ``lambda (1 - lambda) = 0.235``): within 0.1. ``bias.json`` holds it by name."""
    argv = ["--priors", "independent", "--train", "dungeon", "--window", "20", "--sweeps", "40", "--every", "4"]
    doc = po.main([*argv, "--fit-bias", "--out", str(tmp_path)])
    fit = doc["rows"][0]["fit"]
    assert abs(fit["bias"]) < 0.1 and len(fit["steps"]) == 7
    lam = doc["rows"][0]["corpus_share"]
    assert [h for h, _ in fit["steps"]][:2] == [0.0, 1.0 if fit["steps"][0][1] < lam else -1.0]
    saved = json.loads((tmp_path / "bias.json").read_text())
    assert saved["format"] == "ogm_ppl.prior_bias" and saved["bias"] == {"independent:dungeon": fit["bias"]}
