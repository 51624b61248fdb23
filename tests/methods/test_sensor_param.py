"""A sensor by name reaches every model-based method, the command line and experiment specs."""

import json

import numpy as np
import pytest

from ogm_ppl.methods import MapProblem, ParamError, RunContext, get_method, method_names
from ogm_ppl.sensors import (
    GaussianRange,
    PatternMatch,
    register_sensor,
    sensor_by_name,
    sensor_kinds,
    unregister_sensor,
)
from ogm_ppl.testing.kernels import enumerable_2d_data

MODEL_METHODS = ("gibbs", "metropolis", "tempering", "guided_gibbs", "patch_map", "vi")


@pytest.fixture
def wide():
    """A sensor of one's own: the Gaussian range model at three times the method's noise."""
    register_sensor("toy_wide", lambda sigma_cells, p_rand: GaussianRange(3 * sigma_cells, p_rand))
    yield "toy_wide"
    unregister_sensor("toy_wide")


def test_every_method_with_a_model_takes_a_sensor_and_p_rand():
    having = {m for m in method_names() if "sensor" in get_method(m).param_names()}
    assert set(MODEL_METHODS) <= having
    assert {m for m in method_names() if "p_rand" in get_method(m).param_names()} == having
    for name in ("ogm", "amortised"):  # no forward sensor model
        assert "sensor" not in get_method(name).param_names()
    assert get_method("gibbs").default_params().sensor == "gaussian"
    assert get_method("gibbs").default_params().p_rand == 0.0
    assert get_method("vi").default_params().p_rand == 1e-3  # reverse KL needs a likelihood without zeros


@pytest.mark.parametrize("name", MODEL_METHODS)
def test_the_model_of_a_method_is_built_with_the_named_sensor(name, wide):
    problem = MapProblem(*enumerable_2d_data(), 0.9)
    method = get_method(name)
    model = method.parse({"sensor": wide, "p_rand": 0.25}).model(problem)
    assert repr(model.sensor) == "GaussianRange(sigma=2.7, p_rand=0.25)"
    p_rand = 0.001 if name == "vi" else 0.0
    assert repr(method.default_params().model(problem).sensor) == f"GaussianRange(sigma=0.9, p_rand={p_rand})"


def test_a_registered_sensor_maps_as_the_same_sensor_built_in(wide):
    """Gibbs under ``toy_wide`` at sigma 0.9 is Gibbs under ``gaussian`` at 2.7, bit for bit (same seed), and the
    run's details name the sensor."""
    problem = MapProblem(*enumerable_2d_data(), 0.9)
    gibbs = get_method("gibbs")
    a = gibbs.run(gibbs.parse({"sweeps": 40, "sensor": wide}), problem, RunContext(seed=3))
    b = gibbs.run(gibbs.parse({"sweeps": 40, "sigma_cells": 2.7}), problem, RunContext(seed=3))
    c = gibbs.run(gibbs.parse({"sweeps": 40}), problem, RunContext(seed=3))
    assert np.array_equal(a.probabilities, b.probabilities)
    assert not np.array_equal(a.probabilities, c.probabilities)  # the sensor did change the model
    assert a.details["sensor_model"] == b.details["sensor_model"] == "GaussianRange(sigma=2.7, p_rand=0.0)"


def test_an_unknown_sensor_is_refused_with_the_kinds():
    with pytest.raises(ParamError, match=r"unknown sensor kind 'beam'; kinds: gaussian"):
        get_method("gibbs").parse({"sensor": "beam"})


def test_sensor_by_name_checks_its_arguments_and_the_factory():
    assert repr(sensor_by_name("gaussian", 2.0, 0.1)) == "GaussianRange(sigma=2.0, p_rand=0.1)"
    with pytest.raises(ValueError, match="sigma_cells must be positive"):
        sensor_by_name("gaussian", 0.0)
    with pytest.raises(ValueError, match=r"p_rand must lie in \[0, 1\)"):
        sensor_by_name("gaussian", 1.0, 1.0)
    register_sensor("toy_broken", lambda sigma_cells, p_rand: "not a sensor")
    try:
        with pytest.raises(TypeError, match="returned str, not a SensorModel"):
            sensor_by_name("toy_broken")
    finally:
        unregister_sensor("toy_broken")
    with pytest.raises(ValueError, match="shipped sensor kind"):
        unregister_sensor("gaussian")
    with pytest.raises(ValueError, match="already registered"):
        register_sensor("gaussian", lambda sigma_cells, p_rand: PatternMatch(0.9))
    with pytest.raises(ValueError, match="without ':'"):
        register_sensor("a:b", PatternMatch)
    register_sensor("toy_twice", lambda sigma_cells, p_rand: GaussianRange(sigma_cells))
    try:  # another lambda of this module under the same name: refused, not a silent replacement
        with pytest.raises(ValueError, match=r"'toy_twice' is already registered .*<lambda> \(line \d+\)"):
            register_sensor("toy_twice", lambda sigma_cells, p_rand: GaussianRange(5.0))
    finally:
        unregister_sensor("toy_twice")


def test_the_command_line_maps_under_a_sensor_of_ones_own(tmp_path, simulated_dataset, wide, capsys):
    """``--sensor`` (offline and ``--online``) gives the map of the same sensor built in, and the report names
    it; an unknown kind is one error line."""
    from ogm_ppl.cli import load_map, main

    args = ["map", str(simulated_dataset), "--method", "gibbs", "--sweeps", "6", "--seed", "2"]
    load_json = json.loads
    for extra in ([], ["--online"]):
        assert main([*args, *extra, "--sensor", wide, "--sigma", "0.5", "--out", str(tmp_path / "a")]) == 0
        assert main([*args, *extra, "--sigma", "1.5", "--out", str(tmp_path / "b")]) == 0
        a, b = load_map(tmp_path / "a" / "map.npz"), load_map(tmp_path / "b" / "map.npz")
        assert np.array_equal(a["probabilities"], b["probabilities"])
        report = load_json((tmp_path / "a" / "report.json").read_text())
        assert report["method"]["sensor"] == wide
        assert report["method"]["sensor_model"] == "GaussianRange(sigma=1.5, p_rand=0.0)"
        assert report["method"]["sigma_cells"] == 0.5  # the method's, which the registered sensor tripled
    assert main([*args, "--online", "--out", str(tmp_path / "n")]) == 0  # no --sigma: the data's noise, recorded
    method = load_json((tmp_path / "n" / "report.json").read_text())["method"]
    assert method["sensor_model"] == f"GaussianRange(sigma={method['sigma_cells']}, p_rand=0.0)"
    capsys.readouterr()
    assert main(["methods"]) == 0
    assert "\nsensor kinds (parameter sensor): gaussian, toy_wide\n" in capsys.readouterr().out + "\n"
    assert main([*args, "--sensor", "beam", "--out", str(tmp_path / "c")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "unknown sensor kind 'beam'" in err[0]
    assert main(["map", str(simulated_dataset), "--sensor", wide, "--out", str(tmp_path / "d")]) == 2
    assert "--sensor sets the parameter 'sensor' of" in capsys.readouterr().err


def test_a_spec_names_a_sensor(tmp_path, wide):
    import tomllib
    from pathlib import Path

    from ogm_ppl.experiment import parse_spec, run_experiment

    root = Path(__file__).resolve().parents[2]
    d = tomllib.loads((root / "experiments" / "specs" / "smoke.toml").read_text())
    d["algorithms"] = [{"name": "wide", "kind": "gibbs", "sweeps": 3, "sensor": wide, "p_rand": 0.01}]
    d["output"] = {"maps": False, "figures": False}
    r = run_experiment(parse_spec(d, "wide.toml"), tmp_path, scheduler="serial", progress=False)
    wide_model = "GaussianRange(sigma=3.0, p_rand=0.01)"  # the data's noise, 1 cell, times 3
    assert [x["sensor_model"] for x in r.runs] == [wide_model] * len(r.runs)
    d["algorithms"][0]["sensor"] = "beam"
    with pytest.raises(ValueError, match="unknown sensor kind 'beam'"):
        parse_spec(d, "wide.toml")


def test_a_broken_factory_is_refused_where_it_is_registered_or_named():
    """A factory that cannot take ``(sigma_cells, p_rand)`` is refused at registration; one that returns no
    sensor when a method's parameters name it (before any data is read), as one ``ParamError``."""
    from ogm_ppl.sensors import SensorFactoryError

    with pytest.raises(SensorFactoryError, match=r"'toy_one'.*cannot be called as factory\(sigma_cells, p_rand\)"):
        register_sensor("toy_one", lambda sigma: GaussianRange(sigma))
    assert "toy_one" not in sensor_kinds()
    register_sensor("toy_str", lambda sigma_cells, p_rand: "a string")

    def picky(sigma_cells, p_rand):  # a sensor that needs random readings
        if p_rand <= 0:
            raise ValueError("toy_picky needs p_rand > 0")
        return GaussianRange(sigma_cells, p_rand)

    register_sensor("toy_picky", picky)
    try:
        with pytest.raises(
            ParamError, match=r"sensor: the factory of sensor kind 'toy_str' returned str, not a SensorModel"
        ):
            get_method("gibbs").parse({"sensor": "toy_str"})
        assert get_method("gibbs").parse({"sensor": "toy_picky"}).sensor == "toy_picky"  # its ValueError: at run
        with pytest.raises(ValueError, match="toy_picky needs p_rand > 0"):
            sensor_by_name("toy_picky")
        assert sensor_by_name("toy_picky", 1.0, 0.1).p_rand == 0.1
    finally:
        unregister_sensor("toy_str")
        unregister_sensor("toy_picky")


def test_a_sensor_name_sets_its_factorys_options(tmp_path, simulated_dataset, capsys):
    """``KIND:KEY=VALUE,...`` passes numbers to the factory's keyword parameters, through a method's parameters,
    the command line and a spec; a malformed name or an option the factory does not take is refused."""
    from ogm_ppl.cli import main
    from ogm_ppl.sensors import SensorFactoryError, split_sensor_name

    assert split_sensor_name("beam") == ("beam", {})
    assert split_sensor_name("beam:k=3, lam=0.5") == ("beam", {"k": 3, "lam": 0.5})
    assert split_sensor_name(" beam : k = 1_000 ") == ("beam", {"k": 1000})
    for bad in ("beam:k", "beam:k=x", "beam:k=1,k=2", "beam:k=nan", ""):
        with pytest.raises(ValueError):
            split_sensor_name(bad)
    register_sensor("toy_k", lambda sigma_cells, p_rand, k=2.0: GaussianRange(k * sigma_cells, p_rand))
    try:
        assert repr(sensor_by_name("toy_k:k=3", 0.5)) == "GaussianRange(sigma=1.5, p_rand=0.0)"
        with pytest.raises(SensorFactoryError, match=r"does not take the options q"):
            sensor_by_name("toy_k:q=1")
        gibbs = get_method("gibbs")
        problem = MapProblem(*enumerable_2d_data(), 0.9)
        assert repr(gibbs.parse({"sensor": "toy_k:k=4"}).model(problem).sensor).startswith("GaussianRange(sigma=3.6")
        with pytest.raises(ParamError, match="does not take the options q"):
            gibbs.parse({"sensor": "toy_k:q=1"})
        with pytest.raises(ParamError, match="unknown sensor kind 'toy_x'"):
            gibbs.parse({"sensor": "toy_x:k=1"})
        args = ["map", str(simulated_dataset), "--method", "gibbs", "--sweeps", "4"]
        assert main([*args, "--sensor", "toy_k:k=3", "--sigma", "0.5", "--out", str(tmp_path / "a")]) == 0
        assert main([*args, "--sigma", "1.5", "--out", str(tmp_path / "b")]) == 0
        from ogm_ppl.cli import load_map

        a, b = load_map(tmp_path / "a" / "map.npz"), load_map(tmp_path / "b" / "map.npz")
        assert np.array_equal(a["probabilities"], b["probabilities"])
        capsys.readouterr()
        assert main([*args, "--sensor", "toy_k:k=", "--out", str(tmp_path / "c")]) == 2
        assert "option k must be a number" in capsys.readouterr().err
    finally:
        unregister_sensor("toy_k")


def test_an_option_naming_the_factorys_two_arguments_says_where_they_are_set():
    from ogm_ppl.sensors import SensorFactoryError

    with pytest.raises(SensorFactoryError, match=r"first two arguments \(sigma, p_rand\) .* --param p_rand"):
        sensor_by_name("gaussian:p_rand=0.1")
    with pytest.raises(ParamError, match=r"not by the options of a name \(sigma\)"):
        get_method("gibbs").parse({"sensor": "gaussian:sigma=2"})
