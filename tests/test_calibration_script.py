"""experiments/calibration.py, the script form of ``ogm-ppl calibrate``: it runs the library function with the
command's options, and a bad option exits naming it (the library's tests are in tests/calibration)."""

import sys

import pytest
import torch

from tests._scripts import load_experiment


@pytest.fixture(scope="module")
def script():
    threads = torch.get_num_threads()
    yield load_experiment("calibration_experiment", "calibration.py")
    torch.set_num_threads(threads)
    sys.modules.pop("calibration_experiment", None)


def test_the_script_runs_and_refuses_a_bad_option(script, tmp_path, capsys):
    argv = (
        "--test generated --train houseexpo --priors independent --plans 1 --window 36 --generated-shape 80 "
        "--poses 2 --beams 45 --range-cells 30 --sweeps 4 --burn 2 --no-figures"
    ).split()
    res = script.main([*argv, "--out", str(tmp_path)])
    assert {r["prior_name"] for r in res.rows} == {"traditional OGM (p21)", "independent", "independent:houseexpo"}
    assert (tmp_path / "calibration.md").is_file() and res.settings["sweeps"] == 4
    with pytest.raises(SystemExit) as e:
        script.main([*argv, "--sweeps", "3", "--out", str(tmp_path / "x")])
    assert e.value.code == 2 and "--sweeps: must be at least 4" in capsys.readouterr().err
    with pytest.raises(SystemExit, match=r"calibration\.py: .*settings differ in \['sweeps'\]"):
        script.main([*argv[:-5], "--sweeps", "5", "--burn", "2", "--no-figures", "--out", str(tmp_path)])
