"""The ``calibrate`` command: its options map onto CalibrationSettings, it runs the library function, and a bad
option is refused naming its flag."""

import argparse
import json

import pytest
import torch

from ogm_ppl.calibration import CalibrationSettings, calibrate
from ogm_ppl.calibration._command import (
    NAME,
    CalibrateArgumentError,
    add_parser,
    build_parser,
    check_plan_file_arguments,
    run,
    settings_from_args,
)

TINY = (
    "--test generated --train houseexpo --priors independent --plans 1 --window 36 --generated-shape 80 "
    "--poses 2 --beams 45 --range-cells 30 --sweeps 4 --burn 2 --no-figures"
).split()


def _parse(argv):
    parser = argparse.ArgumentParser(prog="ogm-ppl")
    add_parser(parser.add_subparsers(dest="command"))
    return parser.parse_args([NAME, *argv])


def test_the_defaults_are_the_settings_defaults():
    args = _parse([])
    assert settings_from_args(args) == CalibrationSettings() and str(args.out) == "out/calibration"


def test_the_command_runs_the_library_function(tmp_path):
    threads = torch.get_num_threads()
    try:
        assert run(_parse([*TINY, "--out", str(tmp_path / "cmd")])) == 0
    finally:
        torch.set_num_threads(threads)
    doc = json.loads((tmp_path / "cmd" / "calibration.json").read_text())
    s = settings_from_args(_parse(TINY))
    assert s.window == 36 and s.figures is False and s.train == ("houseexpo",)
    lib = calibrate(s, tmp_path / "lib", progress=False)
    assert doc["settings"] == lib.settings
    strip = [{k: v for k, v in r.items() if not k.startswith("seconds")} for r in doc["rows"]]
    assert strip == [{k: v for k, v in r.items() if not k.startswith("seconds")} for r in lib.rows]


@pytest.mark.parametrize(
    "argv, flag",
    [
        (["--sweeps", "3"], "--sweeps"),
        (["--kernel", "tempering", "--beta-min", "1.5"], "--beta-min"),
        (["--kernel", "tempering", "--rungs", "0"], "--rungs"),
        (["--plan-files", "x", "--plan-set", "ipa"], "--plan-set"),
        (["--pixel-size", "0.05"], "--pixel-size"),
        (["--patch", "border1=3"], "--patch"),
    ],
)
def test_a_bad_option_names_its_flag(argv, flag, tmp_path):
    with pytest.raises(CalibrateArgumentError, match=f"^{flag}: "):
        run(_parse([*argv, "--out", str(tmp_path)]))
    assert not any(tmp_path.iterdir())


def test_an_output_path_that_is_a_file_is_refused(tmp_path):
    (tmp_path / "file").write_text("x")
    with pytest.raises(CalibrateArgumentError, match=r"^--out: .*exists and is not a folder"):
        run(_parse([*TINY, "--out", str(tmp_path / "file")]))


def test_plan_file_arguments_of_other_commands_are_checked(capsys):
    ap = build_parser(prog="x")
    with pytest.raises(SystemExit):
        check_plan_file_arguments(ap, ap.parse_args(["--plan-outside", "unknown"]))  # without plan files
    assert "--plan-outside: applies to plan_files only" in capsys.readouterr().err
    check_plan_file_arguments(ap, ap.parse_args(["--plan-files", "x", "--plan-outside", "unknown"]))
