"""The registry of map methods: every method runs through it on a tiny problem and gives a valid map;
parameters are validated with errors that name the key; a method defined in one file reaches the
command line and an experiment spec with no other edit."""

import dataclasses
import json
import os
import subprocess
import sys
import tomllib
from pathlib import Path

import numpy as np
import pytest

from ogm_ppl.datasets import THESIS_TOY_READINGS, toy_1d
from ogm_ppl.datasets.stop_and_scan import stop_and_scan
from ogm_ppl.grid import Grid
from ogm_ppl.methods import (
    MapProblem,
    ParamError,
    RunContext,
    get_method,
    method_names,
    methods,
    register_method,
    unregister_method,
)

from . import toy_method

ROOT = Path(__file__).resolve().parents[2]
# small runs: every sampler 4 sweeps after 1, VI 60 steps
SMALL = {"sweeps": 4, "burn_in": 1, "steps": 60}


@pytest.fixture(scope="module")
def box():
    """A 16 x 16 room (1-cell outer wall, a wall stub inside), 3 stops x 72 beams, sigma 0.5 cell."""
    truth = np.zeros((16, 16), bool)
    truth[[0, -1], :] = truth[:, [0, -1]] = True
    truth[8, 1:6] = True
    grid = Grid(truth.shape, 1.0)
    route = np.array([[4.5, 4.5, 0.0], [11.5, 11.5, 0.0], [4.5, 12.5, 0.0]])
    data = stop_and_scan(truth, grid, route=route, beams=72, max_range_cells=12, sigma_cells=0.5, seed=0)
    return truth.ravel(), MapProblem(grid, data.scans, sigma_cells=0.5)


def small_params(method):
    names = method.param_names()
    return method.parse({k: v for k, v in SMALL.items() if k in names})


def test_the_thesis_methods_and_the_guides_are_registered():
    names = set(method_names())
    for n in (
        "ogm",
        "p21",
        "elfes",
        "patch_map",
        "patch",
        "gibbs",
        "metropolis",
        "vi",
        "amortised",
        "guided_gibbs",
    ):
        assert n in names, n


@pytest.mark.parametrize("name", [n for n in method_names() if get_method(n).stochastic])
def test_every_stochastic_method_takes_a_64_bit_seed(box, name):
    """Experiments derive 64-bit seeds (``derive_seed``); NumPy's seeding takes 32 bits (``vi`` failed in every
    experiment). Seeds below 2^32 keep their runs."""
    _, problem = box
    method = get_method(name)
    result = method.run(small_params(method), problem, RunContext(seed=2**64 - 1))
    assert np.isfinite(result.probabilities).all()


@pytest.mark.parametrize("name", [n for n in method_names() if n != toy_method.NAME])
def test_every_method_maps_a_tiny_room(box, name):
    truth, problem = box
    method = get_method(name)
    result = method.run(small_params(method), problem, RunContext(seed=1))
    p, seen = result.probabilities, result.observed
    K = problem.grid.num_cells
    assert p.shape == (K,) and p.dtype == np.float64 and np.all((p >= 0) & (p <= 1))
    assert seen.shape == (K,) and seen.dtype == bool and seen.any()
    assert set(result.seconds) >= {"ray_cast", "map"} and result.seconds["map"] >= 0
    json.dumps(result.details)  # JSON-able: it goes into report.json and result.json
    # a map, not noise: seen walls are more likely occupied than seen free cells
    assert p[seen & truth].mean() > p[seen & ~truth].mean() + 0.2, name


def test_first_hit_guide_on_the_1d_toy_matches_the_exact_posterior():
    from ogm_ppl import GaussianRange, OccupancyModel
    from ogm_ppl.inference.exact import pose_constrained_1d
    from ogm_ppl.priors import IndependentPrior

    toy = toy_1d(num_cells=20, readings=THESIS_TOY_READINGS)
    problem = MapProblem(toy.grid, toy.scans, sigma_cells=3.0)
    method = get_method("vi")
    params = method.parse({"guide": "first_hit", "steps": 400, "lr": 0.1, "p_rand": 1e-3})
    q = method.run(params, problem).probabilities
    exact = pose_constrained_1d(
        OccupancyModel(toy.grid, problem.rays, GaussianRange(3.0, 1e-3), IndependentPrior(0.5, 20))
    )
    # the first-hit family holds the exact posterior; 400 Adam steps get within 0.02 of it
    assert np.abs(q - exact.marginals.numpy()).max() < 0.02


def test_same_seed_same_map_and_chains_differ(box):
    _, problem = box
    method = get_method("gibbs")
    params = small_params(method)
    a = method.run(params, problem, RunContext(seed=3)).probabilities
    b = method.run(params, problem, RunContext(seed=3)).probabilities
    c = method.run(params, problem, RunContext(seed=4)).probabilities
    assert np.array_equal(a, b) and not np.array_equal(a, c)


# ------------------------------------------------------------------------------------------ validation
@pytest.mark.parametrize("name", [m.name for m in methods() if m.alias_of is None])
def test_unknown_keys_are_refused_by_name(name):
    with pytest.raises(ParamError) as e:
        get_method(name).parse({"no_such_key": 1})
    assert e.value.key == "no_such_key" and "unknown key" in str(e.value)


@pytest.mark.parametrize(
    "name, values, key, message",
    [
        ("gibbs", {"sweeps": 0}, "sweeps", "must be >= 1, got 0"),
        ("gibbs", {"sweeps": 2.5}, "sweeps", "must be an integer"),
        ("gibbs", {"patch": [9, 9]}, "patch", "9 x 9 patches are too large"),
        ("gibbs", {"scan": "diagonal"}, "scan", "must be one of 'systematic'"),
        ("gibbs", {"prior": "crf:houseexpo"}, "prior", "unknown prior kind 'crf'"),
        ("gibbs", {"prior": "mrf:houseexpo", "lam": 0.3}, "lam", "applies to the prior 'independent' only"),
        ("gibbs", {"p_rand_patch": 1.0}, "p_rand_patch", "must be <= 0.999"),
        ("ogm", {"delta": "nonsense"}, "delta", "unknown update term"),
        ("ogm", {"clamp": [3, -2]}, "clamp", "lo < hi"),
        ("ogm", {"delta": "haehnel", "fit": "setting"}, "fit", "cannot refit 'haehnel'"),
        ("ogm", {"prior": True}, "prior", "must be a finite number"),
        ("patch_map", {"mode": "online", "overlap": True}, "overlap", "only the offline patch map"),
        ("metropolis", {"proposal": "endpoint", "scan": "systematic"}, "scan", "use scan = 'random'"),
        ("vi", {"guide": "patch", "loss": "exact"}, "loss", "mean_field or first_hit"),
        ("vi", {"loss": "rws", "p_rand": 0.0}, "p_rand", "p_rand > 0"),
        ("guided_gibbs", {"block": [0, 3]}, "block", "must be [h, w] (positive)"),
        ("guided_gibbs", {"guide": "/no/such/guide.npz"}, "guide", "no such guide file"),
        ("amortised", {"guide": ""}, "guide", "must be a non-empty string"),
    ],
)
def test_bad_values_name_the_key(name, values, key, message):
    with pytest.raises(ParamError) as e:
        get_method(name).parse(values)
    assert e.value.key == key and str(e.value).startswith(f"{key}: ") and message in str(e.value), str(e.value)


@pytest.mark.parametrize("name", ["amortised", "guided_gibbs"])
def test_a_guide_option_names_its_three_forms_and_hints_at_a_corpus(name):
    """``guide`` takes 'shipped', the path of an .npz or 'corpus:CORPUS' (its help says so); a bare corpus name
    that is no file is refused with the hint 'corpus:CORPUS'."""
    method = get_method(name)
    (line,) = [x for x in method.describe() if x.strip().startswith("guide = ")]
    assert "'shipped'" in line and ".npz" in line and "'corpus:CORPUS'" in line, line
    with pytest.raises(ParamError, match=r"^guide: no such guide file: houseexpo; did you mean 'corpus:houseexpo'\?$"):
        method.parse({"guide": "houseexpo"})
    with pytest.raises(ParamError, match="did you mean 'corpus:ipa'"):
        method.parse({"guide": "IPA"})
    with pytest.raises(
        ParamError,
        match=r"no such guide file: nothing\.npz \(a relative path is read from the working directory, .*\); a guide "
        r"is 'shipped', 'corpus:CORPUS'",
    ):
        method.parse({"guide": "nothing.npz"})
    with pytest.raises(ParamError, match=r"no guide learned on corpus 'Dungeon' \(did you mean 'dungeon'\?\)"):
        method.parse({"guide": "corpus:Dungeon"})
    assert method.parse({"guide": "corpus:houseexpo"}).guide == "corpus:houseexpo"


def test_the_amortised_method_checks_the_guides_range_alone_when_the_noise_is_unknown():
    """A corpus guide's sensor setting is checked when a method loads it: the model's range noise only when
    the data or the method gives it (a default stands in otherwise)."""
    import warnings

    from ogm_ppl.inference.variational import FittedSettingWarning

    truth = np.zeros((40, 40), bool)
    truth[[0, -1], :] = truth[:, [0, -1]] = True
    grid = Grid(truth.shape, resolution=0.05)
    data = stop_and_scan(truth, grid, num_poses=2, beams=90, max_range_cells=75, sigma_cells=1.0, seed=0)
    method = get_method("amortised")
    params = method.parse({"guide": "corpus:generated"})  # trained for F = 75 cells, sigma = 3 cells
    with warnings.catch_warnings():
        warnings.simplefilter("error", FittedSettingWarning)
        method.run(params, MapProblem(grid, data.scans), RunContext(seed=0))
    with pytest.warns(FittedSettingWarning, match=r"sigma 1 cells is not within 25% of 3"):
        method.run(params, MapProblem(grid, data.scans, sigma_cells=1.0), RunContext(seed=0))


def test_command_line_strings_are_parsed_by_kind():
    m = get_method("guided_gibbs")
    p = m.parse(
        {
            "sweeps": "7",
            "block": "2x3",
            "random_offset": "no",
            "p_guide": "0.25",
            "patch": "3x3",
            "sigma_cells": "none",
        },
        text=True,
    )
    assert (p.sweeps, p.block, p.random_offset, p.p_guide, p.patch, p.sigma_cells) == (
        7,
        [2, 3],
        False,
        0.25,
        [3, 3],
        None,
    )
    with pytest.raises(ParamError, match=r"^sweeps: expected a whole number, got 'many'"):
        m.parse({"sweeps": "many"}, text=True)
    assert get_method("ogm").parse({"clamp": "-2,3.5"}, text=True).clamp == [-2.0, 3.5]


def test_aliases_preset_parameters_and_can_be_overridden():
    assert get_method("p21").default_params().delta == "p21"
    assert get_method("elfes").parse({"delta": "haehnel"}).delta == "haehnel"
    assert get_method("patch").default_params().overlap is True
    assert get_method("p21").alias_of == "ogm" and get_method("p21").doc == "ogm with delta = 'p21'"


def test_spec_errors_name_the_file_entry_and_key():
    from ogm_ppl.experiment import SpecError, parse_spec

    d = tomllib.loads((ROOT / "experiments" / "specs" / "smoke.toml").read_text())
    d["algorithms"] = [{"name": "v", "kind": "vi", "steps": -1}]
    with pytest.raises(SpecError, match=r"^x\.toml: algorithms\[0\] \('v'\)\.steps: must be >= 1, got -1"):
        parse_spec(d, "x.toml")
    d["algorithms"] = [{"name": "v", "kind": "variational"}]
    with pytest.raises(SpecError, match=r"algorithms\[0\] \('v'\)\.kind: must be one of 'ogm', 'p21'"):
        parse_spec(d, "x.toml")


def test_registering_a_taken_name_is_an_error():
    @dataclasses.dataclass(frozen=True)
    class P:
        pass

    with pytest.raises(ValueError, match="already registered"):
        register_method("gibbs", P)(lambda params, problem, ctx: None)
    with pytest.raises(TypeError, match="param"):

        @dataclasses.dataclass(frozen=True)
        class Q:
            x: int = 3

        register_method("q_method", Q)


def test_command_line_defaults_map_onto_the_parameters():
    from ogm_ppl.cli import build_parser
    from ogm_ppl.cli.map import _method_params as method_params

    parse = build_parser().parse_args
    _, p = method_params(parse(["map", "x.log", "--out", "o", "--method", "gibbs"]))
    assert (p.sweeps, p.burn_in, p.prior, p.lam, p.patch) == (200, 20, "independent", 0.234, 1)
    _, p = method_params(
        parse(
            [
                "map",
                "x.log",
                "--out",
                "o",
                "--method",
                "gibbs",
                "--sweeps",
                "30",
                "--patch",
                "2x2",
                "--prior",
                "mrf:houseexpo",
                "--param",
                "update=metropolised",
            ]
        )
    )
    assert (p.sweeps, p.burn_in, p.lam, p.patch, p.update) == (30, 3, None, [2, 2], "metropolised")
    _, p = method_params(parse(["map", "x.log", "--out", "o", "--method", "elfes"]))
    assert p.delta == "elfes_thesis"


# ------------------------------------------------------------------------------------------ a new method
def test_a_method_in_one_file_reaches_the_command_line(tmp_path, capsys, simulated_dataset):
    from ogm_ppl.cli import load_map, main

    sim = simulated_dataset
    out = tmp_path / "toy"
    assert main(["map", str(sim), "--method", toy_method.NAME, "--param", "level=0.7", "--out", str(out)]) == 0
    m = load_map(out / "map.npz")
    assert set(np.unique(m["probabilities"])) == {0.0, 0.7}
    report = json.loads((out / "report.json").read_text())
    assert report["method"]["name"] == toy_method.NAME and report["method"]["level"] == 0.7
    assert report["method"]["description"].startswith("Cells holding a beam's end point")
    capsys.readouterr()
    assert main(["methods"]) == 0
    listing = capsys.readouterr().out
    assert f"{toy_method.NAME}: Cells holding" in listing and "level = 0.9" in listing
    for name in ("ogm", "gibbs", "vi", "guided_gibbs"):
        assert f"\n{name}: " in "\n" + listing
    assert main(["map", str(sim), "--method", toy_method.NAME, "--param", "level=2", "--out", str(out)]) == 2
    assert "--param level: must be <= 1" in capsys.readouterr().err


def test_a_method_in_one_file_reaches_a_spec(tmp_path):
    from ogm_ppl.experiment import parse_spec, run_experiment

    d = tomllib.loads((ROOT / "experiments" / "specs" / "smoke.toml").read_text())
    d["datasets"][0]["pose_fraction"] = 1.0
    d["algorithms"] = [{"name": "toy", "kind": toy_method.NAME, "level": 0.6}, {"name": "ogm", "kind": "ogm"}]
    d["output"] = {"maps": False, "figures": False}
    r = run_experiment(parse_spec(d, "toy.toml"), tmp_path, scheduler="serial", progress=False)
    runs = {x["algorithm"]: x for x in r.runs}
    assert runs["toy"]["endpoint_cells"] > 0
    scores = {x["algorithm"]: x for x in r.scores}
    assert 0 < scores["toy"]["mask"]["best_f1"] <= 1


def test_environment_variable_names_more_method_modules(tmp_path):
    env = dict(os.environ, OGM_PPL_METHODS="tests.methods.toy_method", PYTHONPATH=str(ROOT))
    r = subprocess.run(
        [sys.executable, "-m", "ogm_ppl", "methods", toy_method.NAME],
        capture_output=True,
        text=True,
        env=env,
        cwd=tmp_path,
        timeout=300,
    )
    assert r.returncode == 0, r.stderr
    assert r.stdout.startswith(f"{toy_method.NAME}: Cells holding")


def test_unregister_removes_a_method_and_its_aliases():
    @dataclasses.dataclass(frozen=True)
    class P:
        pass

    register_method("tmp_method", P, aliases={"tmp_alias": {}})(lambda params, problem, ctx: None)
    assert {"tmp_method", "tmp_alias"} <= set(method_names())
    unregister_method("tmp_method")
    assert not {"tmp_method", "tmp_alias"} & set(method_names())


def test_the_amortised_method_symmetrises_on_request():
    """``symmetrize = true`` averages the corpus guide over the 8 turns and flips: a different map, still
    probabilities, and the same map again on a rerun."""
    truth = np.zeros((40, 40), bool)
    truth[[0, -1], :] = truth[:, [0, -1]] = True
    truth[20, 5:30] = True
    grid = Grid(truth.shape, resolution=0.05)
    data = stop_and_scan(truth, grid, num_poses=2, beams=90, max_range_cells=75, sigma_cells=1.0, seed=0)
    method = get_method("amortised")
    problem = MapProblem(grid, data.scans, sigma_cells=1.0)
    plain = method.run(method.parse({"guide": "corpus:houseexpo"}), problem, RunContext(seed=0)).probabilities
    params = method.parse({"guide": "corpus:houseexpo", "symmetrize": True})
    sym = method.run(params, problem, RunContext(seed=0)).probabilities
    assert sym.shape == plain.shape and ((sym >= 0) & (sym <= 1)).all()
    assert np.abs(sym - plain).max() > 1e-4
    np.testing.assert_array_equal(sym, method.run(params, problem, RunContext(seed=0)).probabilities)
    assert method.parse({"symmetrize": "yes"}, text=True).symmetrize is True


def test_a_shipped_term_on_data_of_unknown_noise_hints_the_refit_that_fit_setting_runs():
    """The data's noise unknown, the shipped p21 is checked on its range alone; its warning's refit call names
    the noise that ``fit = "setting"`` would fit for (the method's default, 1 cell), not the term's own 3."""
    truth = np.zeros((40, 40), bool)
    truth[[0, -1], :] = truth[:, [0, -1]] = True
    grid = Grid(truth.shape, resolution=0.05)
    data = stop_and_scan(truth, grid, num_poses=2, beams=90, max_range_cells=400, sigma_cells=1.0, seed=0)
    from ogm_ppl.inference.variational import FittedSettingWarning

    method = get_method("p21")
    with pytest.warns(FittedSettingWarning, match=r"fit_delta_for_setting\('p21', sigma=1, F=400\)"):
        method.run(method.parse({}), MapProblem(grid, data.scans), RunContext(seed=0))
    with pytest.warns(FittedSettingWarning, match=r"fit_delta_for_setting\('p21', sigma=2, F=400\)"):
        method.run(method.parse({"sigma_cells": 2.0}), MapProblem(grid, data.scans), RunContext(seed=0))
