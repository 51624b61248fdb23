"""``ogm-ppl calibrate`` (:mod:`ogm_ppl.cli.calibrate`): its options map onto CalibrationSettings, it runs the
library function, and a bad option is refused naming its flag, as one error line with exit status 2."""

import json

import pytest
import torch

from ogm_ppl.calibration import CalibrationSettings, calibrate
from ogm_ppl.cli import build_parser as cli_parser
from ogm_ppl.cli import main
from ogm_ppl.cli.calibrate import build_parser, check_plan_file_arguments, settings_from_args

TINY = (
    "--test generated --train houseexpo --priors independent --plans 1 --window 36 --generated-shape 80 "
    "--poses 2 --beams 45 --range-cells 30 --sweeps 4 --burn 2 --no-figures"
).split()


@pytest.fixture(autouse=True)
def _threads():
    threads = torch.get_num_threads()
    yield
    torch.set_num_threads(threads)


def test_the_defaults_are_the_settings_defaults():
    args = cli_parser().parse_args(["calibrate"])
    assert settings_from_args(args) == CalibrationSettings() and str(args.out) == "out/calibration"


def test_the_command_runs_the_library_function(tmp_path, capsys):
    assert main(["calibrate", *TINY, "--out", str(tmp_path / "cmd")]) == 0
    assert f"wrote {tmp_path / 'cmd' / 'calibration.json'}" in capsys.readouterr().out
    doc = json.loads((tmp_path / "cmd" / "calibration.json").read_text())
    s = settings_from_args(cli_parser().parse_args(["calibrate", *TINY]))
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
        (["--rungs", "4"], "--rungs"),
        (["--kernel", "guided", "--beta-min", "0.2"], "--beta-min"),
        (["--kernel", "cycle", "--temper", "both"], "--temper"),
        (["--kernel", "tempering", "--proposal-guide", "ipa"], "--proposal-guide"),
    ],
)
def test_a_bad_option_names_its_flag(argv, flag, tmp_path, capsys):
    assert main(["calibrate", *argv, "--out", str(tmp_path / "out")]) == 2
    assert capsys.readouterr().err.startswith(f"ogm-ppl: error: {flag}: ")
    assert not any(tmp_path.iterdir())


def test_a_samplers_own_option_is_refused_with_another_sampler(capsys):
    assert main(["calibrate", "--kernel", "gibbs", "--rungs", "4"]) == 2
    err = capsys.readouterr().err.strip()
    assert err == "ogm-ppl: error: --rungs: applies to --kernel tempering only, not --kernel gibbs"


def test_a_samplers_own_options_reach_the_settings():
    parse = cli_parser().parse_args
    s = settings_from_args(parse(["calibrate", "--kernel", "tempering", "--rungs", "4", "--beta-min", "0.2"]))
    assert (s.rungs, s.beta_min, s.temper) == (4, 0.2, CalibrationSettings().temper)
    s = settings_from_args(parse(["calibrate", "--kernel", "guided", "--proposal-guide", "ipa@sym"]))
    assert s.proposal_guide == "ipa@sym" and s.rungs == CalibrationSettings().rungs


def test_refusals_of_the_run_are_one_line_errors(tmp_path, capsys):
    (tmp_path / "file").write_text("x")
    assert main(["calibrate", *TINY, "--out", str(tmp_path / "file")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("ogm-ppl: error: --out: ") and "exists and is not a folder" in err
    assert main(["calibrate", *TINY, "--priors", "no_such_kind", "--out", str(tmp_path / "x")]) == 2
    assert "unknown prior kind 'no_such_kind'" in capsys.readouterr().err and not (tmp_path / "x").exists()


def test_plan_file_arguments_of_other_commands_are_checked(capsys):
    ap = build_parser(prog="x")
    with pytest.raises(SystemExit):
        check_plan_file_arguments(ap, ap.parse_args(["--plan-outside", "unknown"]))  # without plan files
    assert "--plan-outside: applies to plan_files only" in capsys.readouterr().err
    check_plan_file_arguments(ap, ap.parse_args(["--plan-files", "x", "--plan-outside", "unknown"]))
