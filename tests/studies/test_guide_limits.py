"""ogm_ppl.studies.guide_limits: per-map NLLs equal the calibration run's for the same guide and map, and the
oracle recalibrations, fitted on the maps they score, are never worse than the guide as it is."""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import ogm_ppl.calibration as cal
from ogm_ppl.calibration import SettingsError
from ogm_ppl.metrics import nll_bits
from ogm_ppl.studies.guide_limits import SHIFTS, TEMPERATURES, guide_limits, recalibrated

SCRIPT = Path(__file__).resolve().parents[2] / "experiments" / "guide_limits.py"


def test_scores_agree_with_calibration_and_oracles_bound_them(tmp_path):
    from ogm_ppl.priors.tables import FITTED_DIR

    shipped = f"ipa={FITTED_DIR}"  # the same guide named with its folder: NAME=DIR
    lines = []
    doc = guide_limits("ipa", ["ipa", "houseexpo", shipped], plans=2, out=tmp_path, log=lines.append)
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
    assert len(lines) == 2 and all(t.name[:40] in line for line, t in zip(lines, maps))
    assert doc["settings"]["guides"] == ["ipa", "houseexpo", shipped] and doc["settings"]["plans"] == 2
    argv = ["--test", "ipa", "--guides", "ipa", "--plans", "1", "--out", str(tmp_path / "script")]
    r = subprocess.run([sys.executable, str(SCRIPT), *argv], capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    back = json.loads((tmp_path / "script" / "guide_limits.json").read_text())
    assert back["rows"][0]["ipa"] == pytest.approx(doc["rows"][0]["ipa"], rel=1e-9)  # the script runs one thread
    assert r.stdout.splitlines()[0] == f"  {maps[0].name[:40]:<40} ipa {back['rows'][0]['ipa']:.3f}"


def test_recalibrated_finds_the_temperature_that_undoes_an_overconfident_guide():
    rng = np.random.default_rng(0)
    true_logits = [rng.normal(0, 2, 400) for _ in range(3)]
    ys = [(rng.random(400) < 1 / (1 + np.exp(-lg))).astype(float) for lg in true_logits]
    over = [2.0 * lg for lg in true_logits]  # twice as confident as the truth: T = 2 undoes it
    nll, T, b = recalibrated(over, ys)
    assert b == 0.0 and 1.5 <= T <= 2.5
    assert nll < np.mean([nll_bits(1 / (1 + np.exp(-lg)), y) for lg, y in zip(over, ys)])
    nll_affine, _, _ = recalibrated(over, ys, SHIFTS)
    assert nll_affine <= nll
    assert TEMPERATURES[0] == 0.5 and TEMPERATURES[-1] == 4.0 and 0.0 in SHIFTS


def test_bad_arguments_are_refused(tmp_path):
    with pytest.raises(SettingsError, match="plans: must be at least 1"):
        guide_limits("ipa", ["ipa"], plans=0, out=tmp_path)
    with pytest.raises(SettingsError, match="test: 'nowhere' is not a test corpus"):
        guide_limits("nowhere", ["ipa"], plans=1)
    (tmp_path / "f").write_text("x")
    with pytest.raises(SettingsError, match=r"out: .*exists and is not a folder"):
        guide_limits("ipa", ["ipa"], out=tmp_path / "f")


def test_the_script_refuses_bad_options_through_the_library(tmp_path):
    (tmp_path / "f").write_text("x")
    for argv, message in (
        (["--plans", "0", "--out", str(tmp_path)], "guide_limits.py: --plans must be at least 1"),
        (["--out", str(tmp_path / "f")], "guide_limits.py: --out [Errno 20] exists and is not a folder"),
    ):
        r = subprocess.run(
            [sys.executable, str(SCRIPT), "--test", "ipa", "--guides", "ipa", *argv],
            capture_output=True,
            text=True,
            timeout=300,
        )
        assert r.returncode == 1 and message in r.stderr, r.stderr
