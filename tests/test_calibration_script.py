"""experiments/calibration.py, the script form of ``ogm-ppl calibrate``: it runs the library function with the
command's options, and a bad option exits naming it (the library's tests are in tests/calibration)."""

import json

from tests._experiments import run_script


def test_the_script_runs_and_refuses_a_bad_option(tmp_path):
    argv = (
        "--test generated --train houseexpo --priors independent --plans 1 --window 36 --generated-shape 80 "
        "--poses 2 --beams 45 --range-cells 30 --sweeps 4 --burn 2 --no-figures"
    ).split()
    r = run_script("calibration.py", *argv, "--out", tmp_path)
    assert r.returncode == 0, r.stderr
    res = json.loads((tmp_path / "calibration.json").read_text())
    assert {row["prior_name"] for row in res["rows"]} == {
        "traditional OGM (p21)",
        "independent",
        "independent:houseexpo",
    }
    assert (tmp_path / "calibration.md").is_file() and res["settings"]["sweeps"] == 4
    bad = run_script("calibration.py", *argv, "--sweeps", "3", "--out", tmp_path / "x")
    assert bad.returncode == 2 and "--sweeps: must be at least 4" in bad.stderr and not (tmp_path / "x").exists()
    other = run_script("calibration.py", *argv[:-5], "--sweeps", "5", "--burn", "2", "--no-figures", "--out", tmp_path)
    assert other.returncode == 1
    assert other.stderr.startswith("calibration.py: ") and "settings differ in ['sweeps']" in other.stderr
