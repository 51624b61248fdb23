"""``TemperedPrior``: ``p~(m)^beta`` of a prior passes the prior contract (its compiled conditionals are the
base's times ``beta``), ``log_prob`` is exactly ``beta`` times the base's, and ``-inf`` stays ``-inf``."""

import math

import numpy as np
import pytest
import torch

from ogm_ppl.priors import BackoffBorderPrior, BorderPatchPrior, MRFPrior, TemperedPrior
from ogm_ppl.testing import PriorContract

from .test_backoff import _table


class TestTemperedBackoff1D(PriorContract):
    num_prior_samples = 8000

    def make_prior(self, num_cells):
        base = BackoffBorderPrior((num_cells,), *_table(2, 2, 1, 0.4), kappa=0.5, back=[0.4, 0.1, 0.2, 0.3], inner=2)
        return TemperedPrior(base, 0.4)


class TestTemperedMRF2D(PriorContract):
    num_prior_samples = 8000

    def make_prior(self, num_cells):
        return TemperedPrior(MRFPrior((2, num_cells // 2), order=1, psi=0.05, cell_prior=0.3), 0.5)


@pytest.mark.parametrize("beta", [0.0, 0.3, 1.0])
def test_log_prob_is_beta_times_the_base(beta):
    base = MRFPrior((2, 3), order=1, psi=0.2, cell_prior=0.4)
    maps = torch.tensor(np.random.default_rng(0).integers(0, 2, (50, 6)), dtype=torch.float64)
    got = TemperedPrior(base, beta).log_prob(maps)
    assert torch.allclose(got, beta * base.log_prob(maps), rtol=0, atol=1e-12)
    assert TemperedPrior(base, beta).normalised is (beta == 1.0 and getattr(base, "normalised", True))


def test_forbidden_maps_stay_forbidden():
    # a sparse table: unseen (border, inner) pairs have no mass at any beta
    b, i, c = _table(2, 2, 3, 0.5)
    base = BorderPatchPrior((6,), b, i, c, inner=2)
    maps = torch.tensor(np.random.default_rng(1).integers(0, 2, (200, 6)), dtype=torch.float64)
    lp = base.log_prob(maps)
    for beta in (0.0, 0.5):
        t = TemperedPrior(base, beta).log_prob(maps)
        assert torch.equal(torch.isinf(t), torch.isinf(lp))
        assert torch.equal(t[torch.isfinite(lp)], beta * lp[torch.isfinite(lp)])


@pytest.mark.parametrize("beta", [-0.1, math.inf, math.nan])
def test_impossible_exponent_refused(beta):
    with pytest.raises(ValueError, match="finite and >= 0"):
        TemperedPrior(MRFPrior((3,), order=1, psi=0.5, cell_prior=0.5), beta)
