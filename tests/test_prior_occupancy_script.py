"""experiments/prior_occupancy.py (the study around ogm_ppl.learn.fit_bias): bad settings are refused."""

import sys

import pytest

from tests._scripts import load_experiment


@pytest.fixture(scope="module")
def po():
    yield load_experiment("prior_occupancy_experiment", "prior_occupancy.py")
    sys.modules.pop("prior_occupancy_experiment", None)


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
