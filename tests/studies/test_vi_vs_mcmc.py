"""ogm_ppl.studies.vi_vs_mcmc on tiny settings: the comparison runs every method and its numbers make sense (the
exact-ELBO first-hit guide reaches the exact posterior on the 1D toy, Gibbs converges with its budget,
traditional OGM is finitely wrong, out-of-fold fits are scored held out)."""

import json
import math
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import pytest
import torch

from ogm_ppl.studies.vi_vs_mcmc import (
    PROBLEMS,
    QUICK,
    ComparisonSettingsError,
    Settings,
    budgets,
    load_results,
    plot,
    run,
    table_md,
    to_json,
    write_results,
)
from ogm_ppl.studies.vi_vs_mcmc.problems import PROBLEMS_2D

SCRIPT = Path(__file__).resolve().parents[2] / "experiments" / "vi_vs_mcmc.py"


def _tiny(problems):
    return replace(
        QUICK,
        problems=problems,
        vi_steps=150,
        vi_steps_sampled=10,
        particles_tracegraph=8,
        particles_rws=16,
        toy_gibbs_sweeps=3000,
        gibbs_sweeps=300,
        walls=20,
        folds=2,
        walls_gibbs_sweeps=300,
        walls_patch_gibbs=2,
        walls_patch_gibbs_sweeps=30,
        walls_vi_exact=1,
        walls_vi_sampled=0,
        walls_vi_steps=100,
        heldout=20,
        delta_max_iter=50,
    )


def _by_name(prob):
    return {r.method: r for r in prob["records"]}


@pytest.fixture(scope="module")
def toy_and_2d():
    torch.set_num_threads(1)
    lines = []
    res = run(_tiny(("toy", "2d:independent")), seed=0, log=lines.append)
    return res, lines


def test_budgets():
    assert budgets(600) == [10, 30, 100, 300, 600]
    assert budgets(1000) == [10, 30, 100, 300, 1000]
    assert budgets(5) == [5]


def test_settings_are_checked():
    assert set(PROBLEMS) == {"toy", "walls", *PROBLEMS_2D} and Settings().problems == PROBLEMS
    for kwargs, match in (
        ({"problems": ("toy", "3d")}, "problems: give distinct problems of toy, walls"),
        ({"problems": ()}, "problems: give distinct problems"),
        ({"folds": 0}, "folds: must be a whole number of at least 1"),
        ({"walls": 3, "folds": 5}, r"folds: must be at most walls \(3\)"),
        ({"gibbs_sweeps": 2}, "gibbs_sweeps: must be at least 3"),
        ({"walls_vi_exact": -1}, "walls_vi_exact: must be a whole number of at least 0"),
    ):
        with pytest.raises(ComparisonSettingsError, match=match):
            replace(QUICK, **kwargs)
    assert replace(QUICK, walls_vi_sampled=0).walls_vi_sampled == 0


def test_toy_and_2d(toy_and_2d, tmp_path):
    res, lines = toy_and_2d
    assert torch.get_default_dtype() == torch.float64  # the conftest's; run restores what it found
    toy = _by_name(res["problems"]["toy"])
    assert toy["exact"].kl == 0.0 and toy["exact"].seconds > 0
    # the first-hit family holds the exact 1D posterior and its ELBO is exact: within the target 0.01
    fh = toy["VI first hit, exact ELBO"]
    assert fh.kl < 0.01 and fh.time_to(0.01) is not None
    assert [p[0] for p in fh.curve] == budgets(150)
    assert all(b[1] > a[1] for a, b in zip(fh.curve, fh.curve[1:]))  # time grows along the curve
    # Gibbs: KL falls with the budget (10 -> 3000 sweeps) and ends near exact
    for name in ("Gibbs (cell, heat bath)", "Gibbs (cell, metropolised)"):
        c = toy[name].curve
        assert c[-1][0] == 3000 and c[-1][2] < c[0][2] / 10 and c[-1][2] < 0.02
    # traditional OGM: finitely wrong; the fitted p21 beats Hähnel's constants
    p21, hae = toy["OGM p21"].kl, toy["OGM Hähnel"].kl
    assert 0 < p21 < math.inf and p21 < hae
    for name, r in toy.items():
        if r.kind != "exact" and not math.isnan(r.kl):
            assert r.kl >= 0 and r.seconds > 0, name
    assert {
        "online patch map L=3",
        "offline overlap L=5",
        "patch Gibbs L=3",
        "VI mean field, RWS",
        "VI patch L=2, TraceGraph",
    } <= set(toy)
    # 2D by brute force
    two = _by_name(res["problems"]["2d:independent"])
    assert res["problems"]["2d:independent"]["latent"] == 13
    g = two["patch Gibbs 2x2"].curve
    assert g[-1][2] < g[0][2]
    assert 0 < two["offline patch map 2x2"].kl < math.inf
    # the progress lines: a title per problem, a line per anytime method
    assert lines[0].startswith("toy: 1D toy") and "  toy done in" in "\n".join(lines)
    assert any(line.startswith("  VI first hit, exact ELBO: KL ") for line in lines)
    # the outputs
    text = table_md({**res, "quick": True})
    assert "VI first hit, exact ELBO" in text and "## 2d:independent" in text
    assert "`ogm_ppl.studies.vi_vs_mcmc.run` (seed 0)" in text  # no command recorded: the function
    assert "`python x.py --quick` (seed 0)" in table_md({**res, "command": "python x.py --quick"})
    back = json.loads(to_json(res))
    assert back["problems"]["toy"]["records"][0]["method"] == "exact"
    plot(res, tmp_path / "kl.png")
    assert (tmp_path / "kl.png").stat().st_size > 10_000


def test_the_files_of_a_run_and_the_script_redraws_them(toy_and_2d, tmp_path):
    res, _ = toy_and_2d
    md = write_results({**res, "quick": True}, tmp_path)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["kl_vs_time.png", "results.json", "table.md"]
    assert (tmp_path / "table.md").read_text() == md
    back = load_results(tmp_path / "results.json")
    assert table_md(back) == md  # the records read back give the same table
    for key, prob in res["problems"].items():
        got = [(r.method, r.kl, r.datasets) for r in back["problems"][key]["records"]]
        assert got == [(r.method, r.kl, r.datasets) for r in prob["records"]], key  # no NaN KL in these
    (tmp_path / "table.md").unlink()
    (tmp_path / "kl_vs_time.png").unlink()
    r = subprocess.run(
        [sys.executable, str(SCRIPT), "--replot", "--out", str(tmp_path)], capture_output=True, text=True, timeout=300
    )
    assert r.returncode == 0, r.stderr
    assert (tmp_path / "table.md").read_text() == md and (tmp_path / "kl_vs_time.png").stat().st_size > 10_000
    r = subprocess.run(
        [sys.executable, str(SCRIPT), "--problems", "toy,3d", "--out", str(tmp_path)],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert r.returncode == 2 and "--problems: give distinct problems" in r.stderr, r.stderr


def test_walls_cross_fitted():
    torch.set_num_threads(1)
    res = run(_tiny(("walls",)), seed=0)
    walls = res["problems"]["walls"]
    recs = _by_name(walls)
    assert recs["OGM p21"].datasets == 20 and recs["patch Gibbs L=3"].datasets == 2
    assert recs["VI first hit, exact ELBO"].datasets == 1
    # VI's model (p_rand = 1e-300) has the thesis's exact posterior
    assert recs["exact posterior under p_rand = 1e-300 (VI's model)"].kl < 1e-6
    h = walls["heldout"]
    for part in ("out_of_fold", "fresh"):
        for name, v in h[part].items():
            if isinstance(v, dict):
                assert v["kl"] > 0 and math.isfinite(v["ce"]), (part, name)
    assert h["out_of_fold"]["p21 (refit, out of fold)"]["ce"] < h["out_of_fold"]["Hähnel"]["ce"]
