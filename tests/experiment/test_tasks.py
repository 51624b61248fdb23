"""The experiment's algorithm tasks: each method's warm-up, prior fingerprints, OGM update terms fitted for
the sensor setting, figures and maps."""

import pytest

from ogm_ppl.experiment import SpecError, parse_spec, run_experiment
from ogm_ppl.experiment import tasks as T
from tests.experiment._smoke import tiny


def _method_names():
    from ogm_ppl.methods import method_names

    return method_names()


@pytest.mark.parametrize("name", _method_names())
def test_the_warm_up_run_of_each_method_succeeds(name):
    """The untimed warm-up (numba compiling kept out of a task's seconds) runs each registered method with its
    default parameters cut down; a warm-up that raised would be skipped silently, so check none does."""
    from ogm_ppl.experiment.spec import AlgorithmSpec

    r = T.warm_run(AlgorithmSpec(name=name, kind=name, params={}), 1.0, 0.05)
    assert r.probabilities is not None and r.probabilities.shape == (24 * 24,)


def test_a_prior_that_cannot_be_fingerprinted_warns():
    """A registered prior built for one grid size only cannot be fingerprinted on the 8 x 8 grid: no digest, and
    a warning that a change of that prior would not be noticed (a spec refuses such a name when it is read)."""
    from types import SimpleNamespace

    from ogm_ppl.priors import IndependentPrior, register_prior, unregister_prior

    def only_64(shape, tables):
        if tuple(shape) != (64, 64):
            raise RuntimeError(f"built for 64 x 64 grids, got {shape}")
        return IndependentPrior(0.3, 64 * 64)

    register_prior("test_only_64", only_64)
    try:
        alg = SimpleNamespace(name="gibbs-64", params={"prior": "test_only_64"})
        with pytest.warns(UserWarning, match="could not be built on an 8 x 8 grid"):
            assert T.algorithm_prior_digest(alg) is None
        assert T.algorithm_prior_digest(SimpleNamespace(name="ogm", params={"prior": 0.4})) is None
        assert len(T.algorithm_prior_digest(SimpleNamespace(name="g", params={"prior": "mrf:houseexpo"}))) == 16
    finally:
        unregister_prior("test_only_64")


def test_ogm_update_terms_fitted_for_the_sensor_setting_or_warned(tmp_path):
    """The smoke dataset's sensor (sigma 1 cell, 30-cell range) is not the shipped p21's (sigma 3, F 75):
    used as shipped it warns and the warning is kept; ``fit = "setting"`` refits p21 there (Section 2.5)."""
    from ogm_ppl.inference.variational import FittedSettingWarning

    d = tiny()
    d["algorithms"] = [
        {"name": "p21", "kind": "ogm", "delta": "p21"},
        {"name": "p21-fit", "kind": "ogm", "delta": "p21", "fit": "setting"},
    ]
    with pytest.warns(FittedSettingWarning, match="p21"):
        r = run_experiment(parse_spec(d, "fit.toml"), tmp_path, scheduler="serial", progress=False)
    runs = {x["algorithm"]: x for x in r.runs}
    assert runs["p21"]["delta_setting"] == {"sigma_cells": 1.0, "F_cells": 30}
    assert any("sigma" in w for w in runs["p21"]["warnings"])
    fitted = runs["p21-fit"]["delta_fitted"]
    assert (fitted["sigma"], fitted["F"]) == (1.0, 30) and "warnings" not in runs["p21-fit"]
    assert len(list((tmp_path / "deltas").glob("delta_p21_sigma1_F30_*.json"))) == 1  # cached for reruns
    with pytest.raises(SpecError, match="cannot refit 'haehnel'"):
        parse_spec({**d, "algorithms": [{"name": "h", "kind": "ogm", "delta": "haehnel", "fit": "setting"}]}, "x")


def test_figures_and_maps(tmp_path):
    d = tiny(maps=True, figures=True, dpi=30)
    d["datasets"][0]["pose_fraction"] = [1.0, 0.5]
    d["algorithms"][1].update(sweeps=2, burn_in=0, chains=1, record=2)
    r = run_experiment(parse_spec(d, "fig.toml"), tmp_path, scheduler="serial", progress=False)
    names = {p.name for p in (tmp_path / "figures").glob("*.png")}
    for n in (
        "pr_office-pf1.png",
        "f1_threshold_office-pf0.5.png",
        "f1_sparsity_office.png",
        "fpfn_office-pf1.png",
        "fpfn_thresholds_office-pf0.5.png",
        "f1_time_office-pf1.png",
    ):
        assert n in names, n
    assert (tmp_path / "tasks/office-pf1/ogm/c0/map.png").exists() and (tmp_path / "maps/office-pf1/ogm.png").exists()
    assert len(r.pooled) == 4
