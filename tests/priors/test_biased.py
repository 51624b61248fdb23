"""``BiasedPrior``: ``p~(m) exp(h sum_k m_k)`` passes the prior contract on every compiled kind it takes (its
compiled conditionals, the tile bundles' sparse and dense tables among them, agree with ``log_prob``), ``log_prob``
is the base's plus ``h`` per occupied cell, patch Gibbs over the tiles of a biased backed-off border table (heat
bath + escape) keeps the brute-force posterior to 1e-12, and a bundle without ``biased`` is refused."""

import math

import numpy as np
import pytest
import torch

from ogm_ppl.priors import BackoffBorderPrior, BiasedPrior, MRFPrior, TemperedPrior
from ogm_ppl.priors.named import prior_by_name
from ogm_ppl.testing import PriorContract

from .test_backoff import _table


class TestBiasedBackoff1D(PriorContract):
    num_prior_samples = 8000

    def make_prior(self, num_cells):
        base = BackoffBorderPrior((num_cells,), *_table(2, 2, 1, 0.4), kappa=0.5, back=[0.4, 0.1, 0.2, 0.3], inner=2)
        return BiasedPrior(base, 0.8)


class TestBiasedTemperedCellGiven8Neighbours2D(PriorContract):
    """A dense window table (backed-off 1-given-8, a third of the borders never seen), tempered, then biased."""

    num_prior_samples = 6000

    def make_prior(self, num_cells):
        b, i, c = _table(8, 1, 2, 0.5)
        keep = b % 3 != 0
        base = BackoffBorderPrior(
            (2, num_cells // 2), b[keep], i[keep], c[keep], kappa=2.0, back=[0.7, 0.3], inner=(1, 1), outside=0
        )
        return BiasedPrior(TemperedPrior(base, 0.6), -0.9)


class TestBiasedMRF2D(PriorContract):
    num_prior_samples = 8000

    def make_prior(self, num_cells):
        return BiasedPrior(MRFPrior((2, num_cells // 2), order=1, psi=0.3, cell_prior=0.3), 0.5)


@pytest.mark.parametrize("h", [0.0, -1.3, 0.7])
def test_log_prob_is_the_base_s_plus_h_per_occupied_cell(h):
    base = MRFPrior((2, 3), order=1, psi=0.2, cell_prior=0.4)
    maps = torch.tensor(np.random.default_rng(0).integers(0, 2, (50, 6)), dtype=torch.float64)
    got = BiasedPrior(base, h).log_prob(maps)
    assert torch.allclose(got, base.log_prob(maps) + h * maps.sum(-1), rtol=0, atol=1e-12)
    assert BiasedPrior(base, h).normalised is (h == 0.0 and getattr(base, "normalised", True))


@pytest.mark.parametrize("name", ["border:houseexpo", "border1:houseexpo", "border_bo:houseexpo", "patch3:houseexpo"])
def test_a_biased_tile_bundle_adds_h_per_occupied_tile_cell(name):
    """Every factor of a real tile table gains ``h`` per occupied cell of the tile's own cells (the inner bits of
    its key), except the border weights of a backed-off table; the fallback's dense table still tables the
    fallback segment; ``-inf`` stays ``-inf``."""
    base = prior_by_name(name, (12, 12)).compiled()
    t = base.biased(0.4)
    inner = base.keys & ((1 << base.n_inner) - 1)
    want = np.where(np.isfinite(base.logp), base.logp + 0.4 * np.array([int(k).bit_count() for k in inner]), base.logp)
    if base.border_seg >= 0:
        a, b = base.seg_off[base.border_seg], base.seg_off[base.border_seg + 1]
        want[a:b] = base.logp[a:b]
    np.testing.assert_allclose(t.logp, want, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(t.back_cdf, base.back_cdf)
    if t.fb_dense.size:
        a, b = t.seg_off[t.fallback], t.seg_off[t.fallback + 1]
        np.testing.assert_array_equal(t.fb_dense[t.keys[a:b]], t.logp[a:b])


def test_patch_gibbs_with_escape_keeps_the_posterior_of_a_biased_backoff_table():
    """The restricted heat bath + escape move over the tiles of a biased backed-off border table: its exact
    one-sweep matrix keeps the brute-force posterior (of ``BiasedPrior.log_prob``) to 1e-12 and moves."""
    from ogm_ppl.inference.mcmc.gibbs import PatchGibbs
    from ogm_ppl.testing.kernels import enumerable_2d
    from ogm_ppl.testing.tile_updates import tile_sweep_matrix

    from ..inference.mcmc.test_backoff_escape import _exact, backoff_prior, with_prior

    model = with_prior(enumerable_2d(), BiasedPrior(backoff_prior((2, 4)), 1.1))
    P = tile_sweep_matrix(PatchGibbs(model, (2, 2), p_escape=0.5))
    pi = _exact(model)
    torch.testing.assert_close(P.sum(1), torch.ones(len(pi), dtype=torch.float64), rtol=0, atol=1e-12)
    torch.testing.assert_close(pi @ P, pi, rtol=0, atol=1e-12)
    assert not torch.allclose(P, torch.eye(len(pi), dtype=torch.float64))


@pytest.mark.parametrize("h", [math.inf, -math.inf, math.nan])
def test_an_infinite_bias_is_refused(h):
    with pytest.raises(ValueError, match="bias must be finite"):
        BiasedPrior(MRFPrior((3,), order=1, psi=0.5, cell_prior=0.5), h)


def test_a_bundle_without_biased_is_refused():
    class Plain(MRFPrior):
        def compiled(self):
            return object()

    with pytest.raises(TypeError, match="has no biased"):
        BiasedPrior(Plain((3,), order=1, psi=0.5, cell_prior=0.5), 0.3).compiled()
