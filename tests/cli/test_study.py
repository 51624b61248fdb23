"""``ogm-ppl study NAME``: the listing names every study, each study's parser has its help and refuses a bad option
in one line (exit status 2) before anything runs, and a run through ``python -m ogm_ppl`` writes what the study's
function returns."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from ogm_ppl.cli import main
from ogm_ppl.cli._studies import STUDIES, build_parser, get_study

#: per study, options its parser refuses (a bad value, a missing argument) before the study runs
BAD_OPTIONS: dict[str, list[str]] = {
    "table_3_1": ["--datasets", "many"],
    "vi_vs_exact_1d": ["--seed", "x"],
    "vi_vs_mcmc": ["--seed", "x"],
    "thesis_border_update": ["--out"],
    "fit_delta_setting": ["--sigma", "x", "--F", "400"],
    "prior_stats": ["--quick=yes"],
    "prior_occupancy": ["--train", "nowhere"],
    "border_chain_probe": ["folder", "dataset", "--sweeps", "x"],
    "path_free": ["--range-cells", "far"],
    "amortised_guide_eval": ["--sweeps", "x"],
    "guide_limits": ["--test", "nowhere", "--guides", "ipa"],
    "unseen_by_distance": ["--kernel", "nowhere"],
    "table_6_4_errors": [],
    "touched_errors": ["folder"],
    "unobserved_marginals": [],
    "map_all_logs": ["--out"],
    "log_plans": ["--min-free-cells", "x"],
    "active_routes": ["out", "--levels", "x"],
    "active_choice_probe": ["out", "--seed", "x"],
    "tune_distance_offset": ["spec.toml"],
}

#: per study, a setting the study refuses before it computes anything, and the message's start
BAD_SETTINGS = [
    ("table_3_1", ["--datasets", "0"], "datasets: must be"),
    ("amortised_guide_eval", ["--sweeps", "0"], "--sweeps: must be at least 1"),
    ("vi_vs_mcmc", ["--problems", "toy,3d"], "--problems: "),
    ("log_plans", ["--min-free-cells", "0"], "--min-free-cells must be at least 1"),
    ("path_free", ["--rows", "5", "--cols", "5"], "rows: rows x cols = 25 cells"),
]


def _one_line_error(capsys, code: int) -> str:
    err = capsys.readouterr().err
    assert code == 2 and len(err.splitlines()) == 1 and err.startswith("ogm-ppl: error: "), err
    return err


def test_the_listing_names_every_study(capsys):
    assert main(["study", "--help"]) == 0
    out = capsys.readouterr().out
    for name, (_, line) in STUDIES.items():
        assert f"  {name}  " in out and line in " ".join(out.split()), name
    assert set(BAD_OPTIONS) == set(STUDIES)


def test_the_installed_command_lists_the_studies():
    r = subprocess.run(
        [sys.executable, "-m", "ogm_ppl", "study", "--help"], capture_output=True, text=True, check=False, timeout=300
    )
    assert r.returncode == 0 and all(name in r.stdout for name in STUDIES), r.stderr


@pytest.mark.parametrize("name", list(STUDIES))
def test_each_study_has_help_and_refuses_a_bad_option(name, capsys):
    assert main(["study", name, "--help"]) == 0
    out = capsys.readouterr().out
    assert out.startswith(f"usage: ogm-ppl study {name}") and get_study(name).description.split()[0] in out
    assert all(a.help for a in build_parser(name, name)._actions), name  # every option says what it is
    _one_line_error(capsys, main(["study", name, *BAD_OPTIONS[name]]))


@pytest.mark.parametrize("name, argv, message", BAD_SETTINGS)
def test_a_setting_the_study_refuses_is_one_line(name, argv, message, capsys, tmp_path):
    code = main(["study", name, *argv, "--out", str(tmp_path / "x")])
    assert message in _one_line_error(capsys, code)
    assert not (tmp_path / "x").exists()


def test_no_study_or_an_unknown_one_is_refused(capsys):
    _one_line_error(capsys, main(["study"]))
    assert "invalid choice" in _one_line_error(capsys, main(["study", "no_such_study"]))


def _command(*args: object) -> subprocess.CompletedProcess:
    cmd = [sys.executable, "-m", "ogm_ppl", "study", *map(str, args)]
    return subprocess.run(cmd, capture_output=True, text=True, check=False, timeout=600)


def _maps(out: Path) -> None:
    """An experiment's folder of two datasets (truth and touched cells) and two algorithms' maps."""
    rng = np.random.default_rng(0)
    (out / "datasets").mkdir(parents=True)
    for i in range(2):
        truth, touched = rng.random((9, 9)) < 0.4, rng.random((9, 9)) < 0.6
        np.savez(out / "datasets" / f"d{i}.eval.npz", truth=truth, touched=touched, mapped=touched)
        (out / "maps" / f"d{i}").mkdir(parents=True)
        q = {"ogm": np.where(touched, truth * 0.8 + 0.1, 0.5), "gibbs": rng.random((9, 9))}
        for alg, m in q.items():
            np.savez(out / "maps" / f"d{i}" / f"{alg}.npz", marginals=m.ravel(), format_version=1)


def test_a_run_writes_what_the_function_returns(tmp_path):
    from ogm_ppl.studies.table_6_4_errors import error_split, error_split_text
    from ogm_ppl.studies.unobserved_marginals import unobserved_means

    _maps(tmp_path / "run")
    r = _command("table_6_4_errors", tmp_path / "run", "--json", tmp_path / "split.json")
    assert r.returncode == 0, r.stderr
    want = error_split(tmp_path / "run")
    assert json.loads((tmp_path / "split.json").read_text()) == json.loads(json.dumps(want))
    assert r.stdout.startswith(error_split_text(want)) and r.stdout.rstrip().endswith(str(tmp_path / "split.json"))
    r = _command("unobserved_marginals", tmp_path / "run", "--json")
    assert r.returncode == 0 and json.loads(r.stdout) == unobserved_means(tmp_path / "run"), r.stderr
    r = _command("unobserved_marginals", tmp_path / "nowhere")
    assert r.returncode == 2 and r.stderr.startswith("ogm-ppl: error: ") and len(r.stderr.splitlines()) == 1


def test_a_computing_study_writes_what_its_function_returns(tmp_path):
    from ogm_ppl.studies.path_free import PathFreeSettings, path_free, path_free_lines

    r = _command("path_free", "--scenes", 2, "--plans", 2, "--priors", "independent:houseexpo", "--out", tmp_path)
    assert r.returncode == 0, r.stderr
    got = json.loads((tmp_path / "path_free.json").read_text())
    settings = PathFreeSettings(scenes=2, plans=2, priors=("independent:houseexpo",))
    want = json.loads(json.dumps(path_free(settings, progress=False)))
    same = ("settings", "scenes", "summary", "by_length", "paths")
    assert {k: got[k] for k in same} == {k: want[k] for k in same}
    assert got["provenance"]["command"].startswith("python -m ogm_ppl study path_free")
    assert "\n".join(path_free_lines(got)) in r.stdout
