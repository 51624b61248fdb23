import numpy as np
import pytest
import torch

from ogm_ppl import GaussianRange, OccupancyModel, raycast
from ogm_ppl.datasets import THESIS_TOY_READINGS, simple_2d_example, toy_1d
from ogm_ppl.inference.exact import brute_force
from ogm_ppl.inference.exact.map_estimate import map_estimate
from ogm_ppl.priors import DataDriven1DPrior, IndependentPrior


def toy_model(K=14, prior=None, readings=THESIS_TOY_READINGS):
    toy = toy_1d(num_cells=K, wall=1, readings=readings)
    prior = prior if prior is not None else IndependentPrior(0.5, K)
    return OccupancyModel(toy.grid, raycast(toy.grid, toy.scans), GaussianRange(3.0), prior)


def assert_local_maximum(model, est):
    base = model.log_joint(est.map).item()
    assert base == pytest.approx(est.log_joint, abs=1e-12)
    flips = est.map.repeat(len(model.latent), 1)
    flips[torch.arange(len(model.latent)), model.latent] = 1 - flips[torch.arange(len(model.latent)), model.latent]
    assert (model.log_joint(flips) <= base + 1e-12).all()


def test_thesis_toy_map_is_the_global_maximum():
    model = toy_model()
    est = map_estimate(model, "occupied")
    assert est.converged
    bf = brute_force(model)
    assert est.log_joint == pytest.approx((bf.log_probs.max() + bf.log_evidence).item(), abs=1e-10)
    assert est.map[1:8].sum() == 0 and est.map[8] == 1  # the wall at f = 8 (Fig. 2.1)


@pytest.mark.parametrize("init", ["occupied", "free", "random"])
@pytest.mark.parametrize("lam", [0.5, 0.234])
def test_every_start_ends_in_a_local_maximum(init, lam):
    model = toy_model(prior=IndependentPrior(lam, 14))
    assert_local_maximum(model, map_estimate(model, init, seed=3))


def test_generic_prior_path():
    model = toy_model(prior=DataDriven1DPrior(14, start=1))
    est = map_estimate(model, "occupied")
    assert_local_maximum(model, est)
    bf = brute_force(model)
    assert est.log_joint == pytest.approx((bf.log_probs.max() + bf.log_evidence).item(), abs=1e-10)


def test_2d_map_and_bad_init():
    ex = simple_2d_example()
    model = OccupancyModel(
        ex.grid, raycast(ex.grid, ex.scans), GaussianRange(3.0), IndependentPrior(0.5, ex.grid.num_cells)
    )
    est = map_estimate(model)
    assert est.converged and np.isfinite(est.log_joint)
    sub = model.latent[torch.randperm(len(model.latent), generator=torch.Generator().manual_seed(0))[:200]]
    flips = est.map.repeat(len(sub), 1)
    flips[torch.arange(len(sub)), sub] = 1 - flips[torch.arange(len(sub)), sub]
    assert (model.log_joint(flips) <= est.log_joint + 1e-9).all()
    assert est.map[model.known_free].sum() == 0
    with pytest.raises(ValueError, match="init"):
        map_estimate(model, "zeros")
    with pytest.raises(ValueError, match="cells"):
        map_estimate(model, torch.zeros(5))


@pytest.mark.parametrize("init", ["occupied", "free", "random"])
def test_the_exact_mode_is_the_map_that_hill_climbing_may_miss(init):
    """``brute_force(model).mode()`` is the most probable map (its log joint the largest of all 2^K); a
    hill-climb ends at or below it."""
    model = toy_model(prior=IndependentPrior(0.234, 14))
    bf = brute_force(model)
    m, p = bf.mode()
    assert p == pytest.approx(bf.log_probs.max().exp().item(), rel=1e-12)
    assert model.log_joint(m).item() == pytest.approx((bf.log_probs.max() + bf.log_evidence).item(), abs=1e-10)
    assert map_estimate(model, init, seed=3).log_joint <= model.log_joint(m).item() + 1e-12
