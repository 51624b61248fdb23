"""The occupancy model behaves as a Pyro user expects."""

import math

import pyro
import pytest
import torch
from pyro import poutine
from pyro.infer import MCMC, Predictive
from pyro.ops.stats import effective_sample_size

from ogm_ppl import GaussianRange, Grid, OccupancyModel, PatternMatch, Scans, raycast
from ogm_ppl.datasets import THESIS_TOY_READINGS, toy_1d
from ogm_ppl.inference.variational.guides import MeanFieldGuide, PatchGuide
from ogm_ppl.priors import IndependentPrior
from ogm_ppl.priors.base import MapPrior

SENSORS = [GaussianRange(3.0, p_rand=1e-3), PatternMatch(0.8)]


def toy_model(sensor, lam=0.3, K=21):
    toy = toy_1d(num_cells=K, readings=THESIS_TOY_READINGS)
    return toy, OccupancyModel(toy.grid, raycast(toy.grid, toy.scans), sensor, IndependentPrior(lam, K))


def random_maps(model, n=16, seed=1):
    maps = (torch.rand(n, model.num_cells, generator=torch.Generator().manual_seed(seed)) < 0.3).double()
    maps[:, model.known_free] = 0
    return maps


@pytest.mark.parametrize("sensor", SENSORS, ids=repr)
def test_readings_are_an_observed_site_scoring_the_likelihood(sensor):
    _, model = toy_model(sensor)
    for m in random_maps(model, 5):
        tr = poutine.trace(poutine.condition(model.model, data={"m": m[model.latent]})).get_trace()
        z = tr.nodes["z"]
        assert z["is_observed"] and torch.equal(z["value"], model.readings)
        assert z["value"].shape == (model.rays.num_rays,)
        assert z["fn"].log_prob(z["value"]).item() == pytest.approx(model.log_likelihood(m).item(), abs=1e-10)
        assert tr.log_prob_sum().item() == pytest.approx(model.log_joint(m).item(), abs=1e-10)


@pytest.mark.parametrize("sensor", SENSORS, ids=repr)
def test_conditioning_on_new_readings_equals_a_model_of_those_readings(sensor):
    toy, model = toy_model(sensor)
    F = toy.scans.max_range
    new = torch.tensor([3.5, 9.0, F, 12.5, 0.0, 19.2])  # a max-range reading among them
    other = OccupancyModel(
        toy.grid,
        raycast(toy.grid, Scans.one_d(new.numpy(), max_range=F, position=0.5)),
        sensor,
        IndependentPrior(0.3, 21),
    )
    maps = random_maps(model)
    cond = poutine.condition(model.model, data={"z": new, "m": maps[:, model.latent]})
    tr = poutine.trace(cond).get_trace()
    torch.testing.assert_close(tr.nodes["z"]["fn"].log_prob(new), other.log_likelihood(maps), rtol=0, atol=1e-10)
    torch.testing.assert_close(model.loglik_table_for(new), other.loglik_table, rtol=0, atol=1e-12)


def test_new_readings_on_rays_cut_by_the_grid_edge_and_in_2d():
    # a 9-cell grid, a 20-cell sensor: readings past the edge recompute their kappa and entry distances
    readings = [3.0, 6.0, 11.0, 17.0, 20.0]
    grid = Grid.line(9)
    model = OccupancyModel(
        grid, raycast(grid, Scans.one_d(readings, max_range=20.0)), PatternMatch(0.7), IndependentPrior(0.3, 9)
    )
    new = torch.tensor([1.0, 14.0, 20.0, 8.0, 2.0])
    other = OccupancyModel(
        grid, raycast(grid, Scans.one_d(new.numpy(), max_range=20.0)), PatternMatch(0.7), IndependentPrior(0.3, 9)
    )
    torch.testing.assert_close(model.loglik_table_for(new), other.loglik_table, rtol=0, atol=1e-12)
    # 2D: the kappa of every observed reading is recomputed exactly, and its table
    g = torch.Generator().manual_seed(3)
    grid = Grid((10, 12), resolution=1.0)
    poses = torch.stack(
        [torch.rand(3, generator=g) * 12, torch.rand(3, generator=g) * 10, torch.rand(3, generator=g) * 6], 1
    )
    scans = Scans(
        poses.numpy(),
        torch.linspace(-3, 3, 25).numpy(),
        (torch.rand(3, 25, generator=g) * 9).numpy(),
        max_range=8.0,
        over_range="max",
    )
    for sensor in (GaussianRange(1.0, 1e-3), PatternMatch(0.8)):
        m2 = OccupancyModel(grid, raycast(grid, scans), sensor, IndependentPrior(0.3, grid.num_cells))
        hit = ~torch.from_numpy(m2.rays.is_max)
        assert torch.equal(m2.range_to_kappa(m2.readings)[hit], torch.from_numpy(m2.rays.z)[hit])
        torch.testing.assert_close(m2.loglik_table_for(m2.readings.clone()), m2.loglik_table, rtol=0, atol=1e-12)


@pytest.mark.parametrize("sensor", SENSORS, ids=repr)
def test_predictive_simulates_readings_and_maps_that_keep_pinned_cells_free(sensor):
    _, model = toy_model(sensor, lam=0.45)
    sim = Predictive(model.model, num_samples=400)(readings=None)
    L, R = len(model.latent), model.rays.num_rays
    assert sim["m"].shape == (400, L) and sim["map"].shape == (400, model.num_cells) and sim["z"].shape == (400, R)
    assert (sim["map"][:, model.known_free] == 0).all()
    assert torch.isfinite(model.log_joint(sim["map"])).all()
    assert sim["m"].mean().item() == pytest.approx(0.45, abs=0.03)
    assert len(torch.unique(sim["z"])) > 50 if sensor.continuous_range else len(torch.unique(sim["z"])) > 10
    par = Predictive(model.model, num_samples=7, parallel=True)(readings=None)
    assert par["z"].shape == (7, R)
    # the unconditioned model (Pyro's habit) simulates as well
    assert not torch.equal(
        poutine.trace(poutine.uncondition(model.model)).get_trace().nodes["z"]["value"], model.readings
    )


def test_simulated_readings_follow_the_range_convention():
    # a wall entered at kappa 8 reads 7.5 cells on average (near face, Gaussian noise)
    grid = Grid.line(30)
    model = OccupancyModel(
        grid, raycast(grid, Scans.one_d([5.0] * 2, max_range=25.0)), GaussianRange(1.0), IndependentPrior(0.3, 30)
    )
    wall = torch.zeros(30)
    wall[8:] = 1
    z = model.simulate_readings(wall.expand(4000, -1), generator=torch.Generator().manual_seed(0))
    assert z.mean().item() == pytest.approx(7.5, abs=4 * 1.0 / math.sqrt(8000))
    empty = model.simulate_readings(torch.zeros(2000, 30), generator=torch.Generator().manual_seed(0))
    # nothing in the 30 cells the 25-cell ray reaches: every reading is max range
    assert (empty == 25.0).all()


def test_prior_predictive_of_a_cut_ray_draws_outside_cells():
    grid = Grid.line(5)
    model = OccupancyModel(
        grid, raycast(grid, Scans.one_d([3.0], max_range=20.0)), PatternMatch(1.0), IndependentPrior(0.5, 5)
    )
    z = model.simulate_readings(torch.zeros(4000, 5), generator=torch.Generator().manual_seed(0))
    # first hit past the edge at kappa 5 + i with probability 0.5^(i+1): the reading is its entry distance
    assert (z >= 4.5).all()
    assert (z == 4.5).double().mean().item() == pytest.approx(0.5, abs=0.04)


def test_mcmc_site_m_over_latent_cells_gives_finite_ess():
    # pinned cells are constant: with them in site "m" Pyro's ESS is NaN for *every* cell
    _, model = toy_model(GaussianRange(3.0, 1e-3), K=8 + 13)
    draws = Predictive(model.model, num_samples=200)(readings=None)
    assert torch.isfinite(effective_sample_size(draws["m"][None], chain_dim=0, sample_dim=1)).all()
    assert torch.isnan(effective_sample_size(draws["map"][None], chain_dim=0, sample_dim=1)).all()


def test_mcmc_site_holds_the_latent_cells_only():
    # the pinned (sensor) cell is no longer a constant column of site "m"; cells the data make certain
    # still are, and Pyro's ESS turns NaN for every column when one is constant (pyro 1.9.2), so per-cell
    # ESS comes from ogm_ppl.inference.mcmc.diagnostics.ess, which is finite for every varying cell
    from ogm_ppl.inference import CellGibbs
    from ogm_ppl.inference.mcmc.diagnostics import ess

    _, model = toy_model(GaussianRange(3.0, 1e-3))
    mcmc = MCMC(CellGibbs(model), num_samples=200, warmup_steps=5, disable_progbar=True)
    mcmc.run()
    m = mcmc.get_samples()["m"]
    assert m.shape == (200, len(model.latent)) and not bool(model.known_free[model.latent].any())
    mcmc.summary()  # runs
    e = ess(mcmc.get_samples(group_by_chain=True)["m"])
    varying = m.std(0) > 0
    assert varying.any() and torch.isfinite(e[varying]).all() and torch.isnan(e[~varying]).all()


def test_every_guide_has_its_own_parameters_and_is_a_pyro_module():
    from pyro.nn import PyroModule

    _, model = toy_model(GaussianRange(3.0, 1e-3))
    a, b = MeanFieldGuide(model), MeanFieldGuide(model)
    p, q = PatchGuide(model, 2), PatchGuide(model, 2)
    for g in (a, b, p, q):
        assert isinstance(g, PyroModule)
    traces = [poutine.trace(g).get_trace() for g in (a, b, p, q)]
    params = [{n for n, site in tr.nodes.items() if site["type"] == "param"} for tr in traces]
    assert all(params) and len(set.union(*params)) == sum(len(x) for x in params)
    assert MeanFieldGuide(model, name="mine").name == "mine"


def test_log_joint_and_check_maps_reject_bad_maps():
    _, model = toy_model(GaussianRange(3.0, 1e-3))
    K = model.num_cells
    good = torch.zeros(K)
    assert torch.isfinite(model.log_joint(good))
    for bad, msg in (
        (torch.zeros(K - 1), "21 cells"),
        (torch.full((K,), 0.5), "only 0 and 1"),
        (torch.full((K,), 2.0), "only 0 and 1"),
        (torch.full((K,), math.nan), "NaN"),
    ):
        with pytest.raises(ValueError, match=msg):
            model.log_joint(bad)
        with pytest.raises(ValueError, match="init map"):
            model.check_maps(bad, what="init map")
    assert model.check_maps(good.bool()).dtype == torch.float64


class NoSample(MapPrior):
    def __init__(self, K):
        self.num_cells = K

    def log_prob(self, maps):
        return torch.zeros(maps.shape[:-1], dtype=torch.float64)


class NaNPrior(NoSample):
    def log_prob(self, maps):
        return torch.full(maps.shape[:-1], math.nan, dtype=torch.float64)

    def sample(self, sample_shape=(), generator=None):
        return torch.full(tuple(sample_shape) + (self.num_cells,), math.nan)


def test_prior_without_sample_or_with_nan_gets_a_clear_error():
    toy = toy_1d(num_cells=10, wall=5, readings=[5.0])
    rays = raycast(toy.grid, toy.scans)
    model = OccupancyModel(toy.grid, rays, GaussianRange(1.0, 1e-3), NoSample(10))
    assert torch.isfinite(model.log_joint(torch.zeros(10)))
    with pytest.raises(TypeError, match="has no sample"):
        Predictive(model.model, num_samples=2)(readings=None)
    bad = OccupancyModel(toy.grid, rays, GaussianRange(1.0, 1e-3), NaNPrior(10))
    with pytest.raises(ValueError, match="NaN"):
        bad.log_joint(torch.zeros(10))
    with pytest.raises(ValueError, match="0/1"):
        Predictive(bad.model, num_samples=2)(readings=None)
    with pytest.raises(ValueError, match="NaN"):
        poutine.trace(poutine.condition(bad.model, data={"m": torch.zeros(9)})).get_trace().log_prob_sum()


@pytest.mark.parametrize(
    "sensor, bad",
    [(GaussianRange(3.0, 1e-3), b) for b in (math.nan, math.inf, -math.inf, 1e3)]
    + [(PatternMatch(0.9), b) for b in (math.nan, -1.0, 1e3)],
)
def test_conditioning_on_readings_that_are_no_ranges_is_refused(sensor, bad):
    """A NaN, an infinity, a range past the max range, or a negative range read by a discrete sensor,
    conditioned on site ``"z"``, is refused naming the ray, not read as a max-range reading."""
    _, model = toy_model(sensor)
    z = model.readings.clone()
    z[2] = bad
    cond = poutine.condition(model.model, data={"z": z})
    with pytest.raises(ValueError, match=r"readings must be ranges in cells .* the first on ray 2"):
        poutine.trace(cond).get_trace().log_prob_sum()


def test_simulated_readings_round_trip_through_conditioning_negative_ranges_included():
    """What ``Predictive`` simulates the model scores: a Gaussian sensor's noise puts first hits near the sensor
    below zero (many of this toy's draws), and conditioning on such readings gives the sensor's own density."""
    _, model = toy_model(GaussianRange(3.0, 1e-3))
    pyro.set_rng_seed(0)
    sim = Predictive(model.model, num_samples=50)(readings=None)
    assert (sim["z"] < 0).any(dim=1).sum() >= 10  # the case at hand occurs in this toy
    for z in sim["z"][(sim["z"] < 0).any(dim=1)]:
        tr = poutine.trace(poutine.condition(model.model, data={"z": z})).get_trace()
        assert torch.isfinite(tr.log_prob_sum())
        i = int(torch.nonzero(z < 0)[0])
        F = torch.tensor(float(model.rays.max_range_cells()[i]), dtype=torch.float64)
        # a first hit in the sensor's own cell (continuous kappa 0, ogm_ppl.sensors): the sensor's log density
        want = model.sensor.log_prob(z[i] + 0.5, torch.tensor(0.0, dtype=torch.float64), F)
        torch.testing.assert_close(model.loglik_table_for(z)[i, 0], want, rtol=1e-12, atol=0)


def test_guides_take_the_models_arguments():
    """A Pyro guide takes the model's arguments: posterior predictive simulation from a guide
    (``readings=None``) and ``SVI.step(readings)`` work with every guide."""
    from pyro.infer import SVI, TraceGraph_ELBO
    from pyro.optim import Adam

    from ogm_ppl.inference.variational.structured_guides import FirstHitGuide

    _, model = toy_model(GaussianRange(3.0, 1e-3))
    for guide in (MeanFieldGuide(model), PatchGuide(model, 2), FirstHitGuide(model)):
        sim = Predictive(model.model, guide=guide, num_samples=5)(readings=None)
        assert sim["z"].shape == (5, model.rays.num_rays) and sim["m"].shape == (5, len(model.latent))
        svi = SVI(model.model, guide, Adam({"lr": 0.01}), TraceGraph_ELBO(num_particles=4))
        assert math.isfinite(svi.step(model.readings))


def test_mcmc_run_refuses_model_arguments_and_counts_each_chain_afresh():
    """``MCMC.run(data)`` would silently sample the kernel's own model: refused. ``diagnostics()`` counts
    each chain's own sweeps."""
    from ogm_ppl.inference import CellGibbs

    _, model = toy_model(GaussianRange(3.0, 1e-3))
    mcmc = MCMC(CellGibbs(model), num_samples=20, warmup_steps=5, disable_progbar=True)
    with pytest.raises(ValueError, match=r"MCMC\.run\(\) takes no model arguments"):
        mcmc.run(model.readings + 5.0)
    mcmc = MCMC(CellGibbs(model), num_samples=20, warmup_steps=5, num_chains=3, disable_progbar=True)
    mcmc.run()
    assert mcmc.diagnostics()["sweeps"] == {f"chain {c}": 25 for c in range(3)}
