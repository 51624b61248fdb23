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


#: float tables of a Tiles bundle that are not log-factors (the escape move's proposal, a probability)
_NOT_LOG_FACTORS = {"back_cdf"}


@pytest.mark.parametrize("name", ["border:houseexpo", "border1:houseexpo", "border_bo:houseexpo", "patch3:houseexpo"])
def test_a_tempered_tile_bundle_scales_every_table_of_log_factors(name):
    """Every float table of log-factors of a tile bundle (the sparse values, the window's dense table and the
    fallback's dense table ``fb_dense``, which the neighbour-layout tile update reads) is ``beta`` times the
    base's, ``-inf`` kept; and ``fb_dense`` still equals the fallback segment's values it tables."""
    from ogm_ppl.priors.named import prior_by_name

    base = prior_by_name(name, (12, 12)).compiled()
    t = base.tempered(0.35)
    for field, v in base._asdict().items():
        if isinstance(v, np.ndarray) and v.dtype.kind == "f" and field not in _NOT_LOG_FACTORS:
            want = np.where(np.isfinite(v), 0.35 * v, v)
            np.testing.assert_array_equal(getattr(t, field), want, err_msg=field)
    if t.fb_dense.size:
        a, b = t.seg_off[t.fallback], t.seg_off[t.fallback + 1]
        np.testing.assert_array_equal(t.fb_dense[t.keys[a:b]], t.logp[a:b])
