import itertools
import math

import pytest
import torch

from ogm_ppl import GaussianRange, OccupancyModel, raycast
from ogm_ppl.datasets import THESIS_TOY_READINGS, toy_1d
from ogm_ppl.inference.exact import pose_constrained_1d
from ogm_ppl.inference.variational.guides import MeanFieldGuide, PatchGuide, fit_guide
from ogm_ppl.metrics import kl_divergence
from ogm_ppl.priors import IndependentPrior
from ogm_ppl.testing import multinomial_goodness_of_fit


def model(K=8, p_rand=1e-3):
    toy = toy_1d(num_cells=K, wall=1, readings=[4.0, 5.0, 4.0])
    return OccupancyModel(
        toy.grid, raycast(toy.grid, toy.scans), GaussianRange(1.5, p_rand=p_rand), IndependentPrior(0.5, K)
    )


def test_patch_distribution_normalises_and_samples():
    m = model(7)
    assert PatchGuide(m, 3).patches.tolist() == [[1, 2, -1], [3, 4, 5], [6, -1, -1]]  # cell 0: the robot
    guide = PatchGuide(m, 3, offset=1)
    assert guide.patches.tolist() == [[1, 2, 3], [4, 5, 6]]
    torch.manual_seed(0)
    logits = torch.randn(2, 8, dtype=torch.float64)
    from ogm_ppl.inference.variational.guides import PatchMapDistribution

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
    m = OccupancyModel(
        toy.grid, raycast(toy.grid, toy.scans), GaussianRange(3.0, p_rand=1e-3), IndependentPrior(0.5, 12)
    )
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


@pytest.mark.parametrize("loss", ["tracegraph", "rws"])
def test_a_guide_drawing_maps_the_prior_gives_no_mass_stops_with_the_reason(loss):
    """Mean-field draws under the thick-wall prior are mostly massless: the loss is not finite within a step or two, and
    fit_guide says why (not a NaN logit a step later)."""
    from ogm_ppl.priors import DataDriven1DPrior

    base = model()
    m = OccupancyModel(base.grid, base.rays, base.sensor, DataDriven1DPrior(8, start=1))
    assert m.prior.can_be_zero
    with pytest.raises(ValueError, match=rf"the {loss} loss is .* at step \d: DataDriven1DPrior gives some maps zero"):
        fit_guide(m, MeanFieldGuide(m), steps=3, num_particles=16, loss=loss)


def test_the_advice_for_a_prior_that_can_be_zero_works():
    """What the error advises for the thick-wall prior (``loss="rws"`` with the first-hit guide) fits."""
    from ogm_ppl.inference.variational.structured_guides import FirstHitGuide
    from ogm_ppl.priors import DataDriven1DPrior

    base = model()
    m = OccupancyModel(base.grid, base.rays, base.sensor, DataDriven1DPrior(8, start=1))
    with pytest.raises(ValueError, match="use loss='rws'"):
        fit_guide(m, FirstHitGuide(m), steps=3, num_particles=16)
    losses = fit_guide(m, FirstHitGuide(m), steps=30, num_particles=64, loss="rws")
    assert all(math.isfinite(v) for v in losses)


def test_patch_guide_needs_a_tiling():
    with pytest.raises(ValueError, match="tiling"):
        PatchGuide(model(), [[0, 0], [0, 2]])


# ----------------------------------------------------------------------- structured guides, exact ELBO
from ogm_ppl.inference.exact.posteriors import _bits, brute_force  # noqa: E402
from ogm_ppl.inference.variational.structured_guides import (  # noqa: E402
    ExactELBO,
    FirstHitGuide,
    FirstHitMapDistribution,
)


def _toy(K=12, lam=0.5):
    toy = toy_1d(num_cells=K, readings=THESIS_TOY_READINGS)
    prior = IndependentPrior(torch.linspace(0.2, 0.6, K)) if lam is None else IndependentPrior(lam, K)
    return OccupancyModel(toy.grid, raycast(toy.grid, toy.scans), GaussianRange(3.0, p_rand=1e-3), prior)


def _brute_elbo(model, dist_):
    L = len(model.latent)
    codes = torch.arange(1 << L)
    vals = _bits(codes, L)
    lq = dist_.log_prob(vals)
    lj = model.log_joint(model.full_map(vals))
    q = lq.exp()
    return float(torch.where(q > 0, q * (lj - lq), 0.0).sum().detach()), float(torch.logsumexp(lq, 0).detach())


def test_first_hit_distribution_normalises_and_samples():
    g = torch.Generator().manual_seed(0)
    order = torch.tensor([2, 0, 4, 1, 3])
    d = FirstHitMapDistribution(torch.randn(6, generator=g), torch.randn(5, generator=g), order)
    maps = _bits(torch.arange(32), 5)
    lp = d.log_prob(maps)
    assert abs(torch.logsumexp(lp, 0).item()) < 1e-12
    torch.manual_seed(1)
    s = d.sample((20000,))
    counts = torch.bincount((s * (2 ** torch.arange(5))).sum(-1).long(), minlength=32).double()
    assert multinomial_goodness_of_fit(lp.exp(), counts) > 1e-3
    torch.testing.assert_close(d.marginals(), (lp.exp()[:, None] * maps).sum(0), rtol=0, atol=1e-12)


@pytest.mark.parametrize("make", [FirstHitGuide, MeanFieldGuide])
def test_closed_form_elbo_equals_the_enumerated_expectation(make):
    model = _toy(K=9, lam=None)
    guide = make(model)
    g = torch.Generator().manual_seed(2)
    with torch.no_grad():
        for p in guide.parameters():
            p.copy_(torch.randn(p.shape, generator=g))
    d = (
        guide.distribution()
        if isinstance(guide, FirstHitGuide)
        else __import__("pyro").distributions.Bernoulli(logits=guide.logits).to_event(1)
    )
    expected, norm = _brute_elbo(model, d)
    assert abs(norm) < 1e-12
    assert guide.exact_elbo(model).item() == pytest.approx(expected, abs=1e-9)


def test_mean_field_closed_form_elbo_on_2d_rays():
    import math as _m

    from ogm_ppl import Grid, Scans

    grid = Grid((3, 3), resolution=1.0)
    scans = Scans(
        [[0.5, 0.5, 0.0], [0.5, 0.5, _m.pi / 2], [2.5, 2.5, _m.pi], [2.5, 1.5, _m.pi]],
        [0.0],
        [[1.2], [2.0], [1.5], [0.9]],
        max_range=2.5,
    )
    model = OccupancyModel(
        grid, raycast(grid, scans), GaussianRange(0.8, 1e-3), IndependentPrior(torch.linspace(0.2, 0.7, 9))
    )
    guide = MeanFieldGuide(model)
    with torch.no_grad():
        guide.logits.copy_(torch.randn(len(model.latent), generator=torch.Generator().manual_seed(5)))
    import pyro.distributions as pd

    expected, _ = _brute_elbo(model, pd.Bernoulli(logits=guide.logits.detach()).to_event(1))
    assert guide.exact_elbo(model).item() == pytest.approx(expected, abs=1e-9)
    assert brute_force(model).log_evidence >= expected


def test_first_hit_family_holds_the_exact_posterior_and_exact_elbo_finds_it():
    model = _toy(K=21)
    post = pose_constrained_1d(model)
    exact = post.marginals
    # the exact posterior, set by hand: q(f) = p(f | z) over the latent cells, cells behind at the prior
    guide = FirstHitGuide(model)
    with torch.no_grad():
        guide.f_logits.copy_(post.log_pf[1:].clamp(min=-700))  # cell 0 (the robot) is pinned
        guide.behind_logits.zero_()
    torch.testing.assert_close(guide.marginals(), exact, rtol=0, atol=1e-9)
    assert guide.exact_elbo(model).item() == pytest.approx(post.log_evidence, abs=1e-9)
    fitted = FirstHitGuide(model)
    fit_guide(model, fitted, steps=300, lr=0.1, loss="exact")
    assert float(kl_divergence(exact[1:], fitted.marginals()[1:].clamp(1e-9, 1 - 1e-9))) < 0.01


def test_rws_fits_the_first_hit_guide():
    model = _toy(K=12)
    exact = pose_constrained_1d(model).marginals
    guide = FirstHitGuide(model)
    fit_guide(model, guide, steps=150, lr=0.05, num_particles=128, loss="rws")
    start = float(kl_divergence(exact[1:], torch.full((11,), 0.5)))
    assert float(kl_divergence(exact[1:], guide.marginals()[1:].clamp(1e-9, 1 - 1e-9))) < 0.1 * start


def test_exact_elbo_and_first_hit_guide_refuse_what_they_cannot_do():
    class Correlated(IndependentPrior):
        def cell_log_odds(self):
            return None

    toy = toy_1d(num_cells=8, wall=3, readings=[4.0])
    m = OccupancyModel(toy.grid, raycast(toy.grid, toy.scans), GaussianRange(1.0, 1e-3), Correlated(0.5, 8))
    with pytest.raises(TypeError, match="independent"):
        fit_guide(m, FirstHitGuide(m), steps=1, loss="exact")
    with pytest.raises(TypeError, match="exact_elbo"):
        fit_guide(m, PatchGuide(m, 2), steps=1, loss="exact")
    with pytest.raises(ValueError, match="loss"):
        fit_guide(m, MeanFieldGuide(m), steps=1, loss="kl")
    assert isinstance(ExactELBO(), __import__("pyro").infer.ELBO)


def test_mean_field_closed_form_elbo_has_finite_gradients_with_padded_rays():
    """Rays of unequal length pad the likelihood table with -inf; the ELBO's gradient stays finite
    (it was NaN: 0 * -inf in the padding)."""
    import math as _m

    from ogm_ppl import Grid, Scans

    grid = Grid((4, 4), resolution=1.0)
    scans = Scans(
        [[0.5, 0.5, 0.0], [0.5, 0.5, 0.7], [3.5, 3.5, _m.pi], [3.5, 3.5, -2.0], [0.5, 3.5, -0.6]],
        [0.0],
        [[2.6], [3.3], [2.2], [1.3], [2.9]],
        max_range=4.0,
        over_range="max",
    )
    model = OccupancyModel(grid, raycast(grid, scans), GaussianRange(0.8, 1e-3), IndependentPrior(0.4, 16))
    assert torch.isinf(model.loglik_table).any()
    guide = MeanFieldGuide(model)
    guide.exact_elbo(model).backward()
    assert torch.isfinite(guide.logits.grad).all()
