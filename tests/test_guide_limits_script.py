"""experiments/guide_limits.py: per-map NLLs equal the calibration run's for the same guide and map, and the oracle
recalibrations, fitted on the maps they score, are never worse than the guide as it is."""

import json
import sys

import pytest

import ogm_ppl.calibration as cal
from tests._scripts import load_experiment


@pytest.fixture(scope="module")
def gl():
    yield load_experiment("guide_limits_experiment", "guide_limits.py")
    sys.modules.pop("guide_limits_experiment", None)


def test_scores_agree_with_calibration_and_oracles_bound_them(gl, tmp_path):
    from ogm_ppl.priors.tables import FITTED_DIR

    shipped = f"ipa={FITTED_DIR}"  # the same guide named with its folder: NAME=DIR
    doc = gl.main(["--test", "ipa", "--guides", "ipa", "houseexpo", shipped, "--plans", "2", "--out", str(tmp_path)])
    args = cal.CalibrationSettings(plans=2)
    maps = cal.heldout_maps("ipa", 2, args.window)
    for row, t in zip(doc["rows"], maps, strict=True):
        scored = cal.run_guide(cal.make_scene(t, args), cal.guide_for("ipa"), args.sigma)["scores"]["unseen"]
        assert row["plan"] == t.name and row["ipa"] == pytest.approx(scored["nll_bits"], rel=1e-12)
        assert row["unseen_cells"] == scored["cells"]
    assert doc["summary"][shipped] == doc["summary"]["ipa"]
    for g in ("ipa", "houseexpo"):
        s = doc["summary"][g]
        assert s["nll_oracle_affine"] <= s["nll_oracle_temperature"] + 1e-12 <= s["nll"] + 2e-12
    assert json.loads((tmp_path / "guide_limits.json").read_text())["summary"] == doc["summary"]


def test_bad_arguments_are_refused(gl, tmp_path):
    with pytest.raises(SystemExit, match="--plans must be at least 1"):
        gl.main(["--test", "ipa", "--guides", "ipa", "--plans", "0", "--out", str(tmp_path)])
    (tmp_path / "f").write_text("x")
    with pytest.raises(SystemExit, match=r"--out .*exists and is not a folder"):
        gl.main(["--test", "ipa", "--guides", "ipa", "--out", str(tmp_path / "f")])
