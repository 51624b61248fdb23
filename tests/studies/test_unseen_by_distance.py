"""ogm_ppl.studies.unseen_by_distance: the bins split the unseen cells, and their NLLs weighted by their shares
give the NLL the calibration run scores for the same guide (or prior) on the same map."""

import dataclasses
import json
import subprocess
import sys
from pathlib import Path

import pytest

import ogm_ppl.calibration as cal
from ogm_ppl.calibration import SettingsError
from ogm_ppl.studies.unseen_by_distance import DistanceSettings, rows_table, unseen_by_distance

SCRIPT = Path(__file__).resolve().parents[2] / "experiments" / "unseen_by_distance.py"


def test_bins_add_up_to_the_calibration_score(tmp_path):
    doc = unseen_by_distance(DistanceSettings(guide="houseexpo", test=("houseexpo",), plans=1), tmp_path)
    rows = doc["rows"]
    assert [r["distance"] for r in rows] == [[0.0, 1.5], [1.5, 3.0], [3.0, 6.0], [6.0, None]]
    assert sum(r["share"] for r in rows) == pytest.approx(1.0, abs=1e-12)
    pooled = sum(r["share"] * r["nll_bits"] for r in rows)
    args = cal.CalibrationSettings(plans=1)
    scene = cal.make_scene(cal.heldout_maps("houseexpo", 1, args.window)[0], args)
    scored = cal.run_guide(scene, cal.guide_for("houseexpo"), args.sigma)["scores"]["unseen"]["nll_bits"]
    assert pooled == pytest.approx(scored, rel=1e-6)  # two ways to the same mean over one map's unseen cells
    assert json.loads((tmp_path / "unseen_by_distance.json").read_text())["rows"] == rows
    assert doc["settings"]["guide"] == "houseexpo" and doc["settings"]["plans"] == 1
    text = rows_table(rows, "guide:houseexpo").splitlines()
    assert text[0].startswith("guide:houseexpo, unseen cells by distance") and len(text) == 2 + len(rows)
    assert text[-1].split()[:3] == ["houseexpo", "(6,", "inf]"]
    argv = ["--guide", "houseexpo", "--test", "houseexpo", "--plans", "1", "--out", str(tmp_path / "script")]
    r = subprocess.run([sys.executable, str(SCRIPT), *argv], capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    back = json.loads((tmp_path / "script" / "unseen_by_distance.json").read_text())["rows"]
    assert [{**r, "nll_bits": None} for r in back] == [{**r, "nll_bits": None} for r in rows]
    assert [r["nll_bits"] for r in back] == pytest.approx([r["nll_bits"] for r in rows], rel=1e-9)
    assert r.stdout.startswith(rows_table(back, "guide:houseexpo") + "\nwrote ")


def test_no_maps_is_refused():
    with pytest.raises(SettingsError, match="plans: must be at least 1"):
        DistanceSettings(plans=0)


def test_chain_bins_add_up_to_the_calibration_score_and_agreement(tmp_path):
    """A prior's chains, two lengths from the same seeds: per length, the bins' NLLs and agreement shares
    weighted by their cell shares equal the calibration run's NLL and R-hat share for the same prior, sampler,
    sweeps and map."""
    s = DistanceSettings(prior="border_bo", kernel="gibbs", sweeps=(8, 12), test=("houseexpo",), plans=1)
    lines = []
    doc = unseen_by_distance(s, tmp_path, log=lines.append)
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
    assert len(lines) == 2 and "border_bo:houseexpo 8 sweeps: agree" in lines[0]
    assert "chain occupancy (ogm, free, prior)" in rows_table(doc["rows"], "border_bo").splitlines()[1]


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"sweeps": (2,)}, "sweeps: must be at least 4"),
        ({"burn": -1}, "burn: must be at least 0"),
        ({"prior": "border_bo", "guide": "houseexpo"}, "not both"),
        ({"kernel": "nope"}, "kernel: 'nope' is not a sampler"),
        ({"test": ("nowhere",)}, "test: 'nowhere' is not a test corpus"),
        ({"pixel_size": 0.05}, "pixel_size: applies to plan_files only"),
    ],
)
def test_bad_chain_settings_are_refused(kwargs, match):
    with pytest.raises(SettingsError, match=match):
        DistanceSettings(**kwargs)


def test_plan_files_are_binned_as_calibration_scores_them(tmp_path):
    from tests._plan_folder import write_plan_folder

    d = write_plan_folder(tmp_path)
    s = DistanceSettings(guide="houseexpo", plan_files=(d,), plan_set="mine", pixel_size=0.025, plans=1)
    doc = unseen_by_distance(s, tmp_path / "out")
    rows = doc["rows"]
    assert {r["test"] for r in rows} == {"mine"} and doc["settings"]["plan_set"] == "mine"
    args = cal.CalibrationSettings(plans=1, plan_files=(d,), plan_set="mine", pixel_size=0.025)
    scene = cal.make_scene(cal.plan_set_maps(args, 1)[0], args)
    scored = cal.run_guide(scene, cal.guide_for("houseexpo"), args.sigma)["scores"]["unseen"]["nll_bits"]
    assert sum(r["share"] * r["nll_bits"] for r in rows) == pytest.approx(scored, rel=1e-6)
    with pytest.raises(SettingsError, match="no prior is learned on the plan set"):
        unseen_by_distance(DistanceSettings(prior="patch3", plan_files=(d,), pixel_size=0.025), tmp_path / "x")
    assert not (tmp_path / "x").exists()


@pytest.mark.parametrize(
    "argv, message",
    [
        (["--sweeps", "2"], "--sweeps: must be at least 4"),
        (["--plans", "0"], "--plans: must be at least 1"),
        (["--prior", "border_bo", "--guide", "houseexpo"], "not allowed with argument"),
    ],
)
def test_the_script_refuses_bad_options(tmp_path, argv, message):
    r = subprocess.run(
        [sys.executable, str(SCRIPT), *argv, "--out", str(tmp_path)], capture_output=True, text=True, timeout=300
    )
    assert r.returncode == 2 and message in r.stderr, r.stderr
