"""experiments/unseen_by_distance.py: the bins split the unseen cells, and their NLLs weighted by their shares
give the NLL the calibration run scores for the same guide on the same map."""

import dataclasses
import json
import sys

import pytest

import ogm_ppl.calibration as cal
from tests._scripts import load_experiment


@pytest.fixture(scope="module")
def ubd():
    yield load_experiment("unseen_by_distance_experiment", "unseen_by_distance.py")
    sys.modules.pop("unseen_by_distance_experiment", None)


def test_bins_add_up_to_the_calibration_score(ubd, tmp_path):
    doc = ubd.main(["--guide", "houseexpo", "--test", "houseexpo", "--plans", "1", "--out", str(tmp_path)])
    rows = doc["rows"]
    assert [r["distance"] for r in rows] == [[0.0, 1.5], [1.5, 3.0], [3.0, 6.0], [6.0, None]]
    assert sum(r["share"] for r in rows) == pytest.approx(1.0, abs=1e-12)
    pooled = sum(r["share"] * r["nll_bits"] for r in rows)
    args = cal.CalibrationSettings(plans=1)
    scene = cal.make_scene(cal.heldout_maps("houseexpo", 1, args.window)[0], args)
    scored = cal.run_guide(scene, cal.guide_for("houseexpo"), args.sigma)["scores"]["unseen"]["nll_bits"]
    assert pooled == pytest.approx(scored, rel=1e-6)  # two ways to the same mean over one map's unseen cells
    assert json.loads((tmp_path / "unseen_by_distance.json").read_text())["rows"] == rows


def test_no_maps_is_refused(ubd, tmp_path):
    with pytest.raises(SystemExit, match="--plans must be at least 1"):
        ubd.main(["--plans", "0", "--out", str(tmp_path)])


def test_chain_bins_add_up_to_the_calibration_score_and_agreement(ubd, tmp_path):
    """A prior's chains, two lengths from the same seeds: per length, the bins' NLLs and agreement shares
    weighted by their cell shares equal the calibration run's NLL and R-hat share for the same prior, sampler,
    sweeps and map."""
    argv = ["--prior", "border_bo", "--kernel", "gibbs", "--sweeps", "8", "12", "--test", "houseexpo"]
    doc = ubd.main([*argv, "--plans", "1", "--out", str(tmp_path)])
    base = cal.CalibrationSettings(plans=1, kernel="gibbs")
    scene = cal.make_scene(cal.heldout_maps("houseexpo", 1, base.window)[0], base)
    for S in (8, 12):
        rows = [r for r in doc["rows"] if r["sweeps"] == S]
        assert len(rows) == 4 and {r["prior"] for r in rows} == {"border_bo:houseexpo"}
        assert sum(r["share"] for r in rows) == pytest.approx(1.0, abs=1e-12)
        got = cal.run_prior(scene, "border_bo:houseexpo", dataclasses.replace(base, sweeps=S, burn=S // 4))
        assert sum(r["share"] * r["nll_bits"] for r in rows) == pytest.approx(
            got["scores"]["unseen"]["nll_bits"], rel=1e-6
        )
        assert sum(r["share"] * r["agree"] for r in rows) == pytest.approx(got["rhat_below"], abs=1e-12)
        assert all(len(r["chain_occupied"]) == 3 and all(0 <= v <= 1 for v in r["chain_occupied"]) for r in rows)
    assert doc["settings"]["prior"] == "border_bo" and doc["settings"]["sweeps"] == [8, 12]


@pytest.mark.parametrize(
    "argv, match",
    [
        (["--sweeps", "2"], "--sweeps must be at least 4"),
        (["--prior", "border_bo", "--guide", "houseexpo"], "not allowed with argument"),
    ],
)
def test_bad_chain_settings_are_refused(ubd, tmp_path, argv, match, capsys):
    with pytest.raises(SystemExit):
        ubd.main([*argv, "--out", str(tmp_path)])
    if "not allowed" in match:
        assert match in capsys.readouterr().err


def test_plan_files_are_binned_as_calibration_scores_them(ubd, tmp_path):
    from tests._scripts import write_plan_folder

    d = write_plan_folder(tmp_path)
    argv = ["--guide", "houseexpo", "--plan-files", str(d), "--plan-set", "mine", "--pixel-size", "0.025"]
    doc = ubd.main([*argv, "--plans", "1", "--out", str(tmp_path / "out")])
    rows = doc["rows"]
    assert {r["test"] for r in rows} == {"mine"} and doc["settings"]["plan_set"] == "mine"
    args = cal.CalibrationSettings(plans=1, plan_files=(d,), plan_set="mine", pixel_size=0.025)
    scene = cal.make_scene(cal.plan_set_maps(args, 1)[0], args)
    scored = cal.run_guide(scene, cal.guide_for("houseexpo"), args.sigma)["scores"]["unseen"]["nll_bits"]
    assert sum(r["share"] * r["nll_bits"] for r in rows) == pytest.approx(scored, rel=1e-6)
    with pytest.raises(SystemExit, match="no prior is learned on the plan set"):
        ubd.main(["--prior", "patch3", "--plan-files", str(d), "--pixel-size", "0.025", "--out", str(tmp_path)])
