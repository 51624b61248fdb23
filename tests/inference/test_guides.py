import itertools

import pytest
import torch
from pyro.distributions.testing.gof import multinomial_goodness_of_fit

from ogm_ppl import GaussianRange, OccupancyModel, raycast
from ogm_ppl.datasets import THESIS_TOY_READINGS, toy_1d
from ogm_ppl.inference.exact import pose_constrained_1d
from ogm_ppl.inference.guides import MeanFieldGuide, PatchGuide, fit_guide
from ogm_ppl.metrics import kl_divergence
from ogm_ppl.priors import IndependentPrior


def model(K=8, p_rand=1e-3):
    toy = toy_1d(num_cells=K, wall=1, readings=[4.0, 5.0, 4.0])
    return OccupancyModel(toy.grid, raycast(toy.grid, toy.scans), GaussianRange(1.5, p_rand=p_rand),
                          IndependentPrior(0.5, K))  # fmt: skip


def test_patch_distribution_normalises_and_samples():
    m = model(7)
    assert PatchGuide(m, 3).patches.tolist() == [[1, 2, -1], [3, 4, 5], [6, -1, -1]]  # cell 0: the robot
    guide = PatchGuide(m, 3, offset=1)
    assert guide.patches.tolist() == [[1, 2, 3], [4, 5, 6]]
    torch.manual_seed(0)
    logits = torch.randn(2, 8, dtype=torch.float64)
    from ogm_ppl.inference.guides import PatchMapDistribution

    d = PatchMapDistribution(logits, guide.patches, 7)
    maps = torch.tensor(list(itertools.product([0.0, 1.0], repeat=6)), dtype=torch.float64)
    maps = torch.cat([torch.zeros(64, 1, dtype=torch.float64), maps], 1)
    lp = d.log_prob(maps)
    assert abs(torch.logsumexp(lp, 0).item()) < 1e-12
    s = d.sample((20000,))
    codes = (s[:, 1:] * (2 ** torch.arange(5, -1, -1))).sum(-1).long()
    counts = torch.bincount(codes, minlength=64).double()
    assert multinomial_goodness_of_fit(lp.exp(), counts) > 1e-3
    torch.testing.assert_close(d.marginals(), s.mean(0), rtol=0, atol=4 * 0.5 / 20000**0.5)


@pytest.mark.parametrize("make", [lambda m: MeanFieldGuide(m), lambda m: PatchGuide(m, 2)])
def test_svi_fits_the_exact_posterior_approximately(make):
    toy = toy_1d(num_cells=12, readings=THESIS_TOY_READINGS)
    m = OccupancyModel(toy.grid, raycast(toy.grid, toy.scans), GaussianRange(3.0, p_rand=1e-3), IndependentPrior(0.5, 12))
    exact = pose_constrained_1d(m).marginals
    guide = make(m)
    q0 = guide.marginals() if isinstance(guide, MeanFieldGuide) else None
    losses = fit_guide(m, guide, steps=600, lr=0.1, num_particles=128, seed=0)
    q = guide.marginals().clamp(1e-9, 1 - 1e-9)
    kl = float(kl_divergence(exact[1:], q[1:]))
    start = float(kl_divergence(exact[1:], torch.full((11,), 0.5)))
    assert sum(losses[-100:]) / 100 < sum(losses[:100]) / 100
    assert kl < 0.25 * start, (kl, start)
    assert q0 is None or not torch.equal(q0, q)


def test_refuses_models_with_impossible_maps():
    with pytest.raises(ValueError, match="p_rand"):
        fit_guide(model(p_rand=0.0), MeanFieldGuide(model(p_rand=0.0)), steps=1)


def test_patch_guide_needs_a_tiling():
    with pytest.raises(ValueError, match="tiling"):
        PatchGuide(model(), [[0, 0], [0, 2]])
