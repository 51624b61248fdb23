"""The border index of sparse tile tables (:func:`border_index`): every factor, with and without it, and
every border's candidate run against a search of the sorted keys."""

from __future__ import annotations

import numpy as np
import pytest

from ogm_ppl.priors import BorderPatchPrior
from ogm_ppl.priors.backoff import BackoffBorderPrior
from ogm_ppl.priors.compiled.tile_factors import border_range, sparse_key_log_factor


def _border_prior(seed):
    # 3 x 3 inners given 16 border cells (25-cell windows: no dense table), half the borders seen
    rng = np.random.default_rng(seed)
    b = rng.integers(0, 1 << 16, 400)
    i = rng.integers(0, 512, 400)
    c = rng.integers(1, 20, 400).astype(float)
    return BorderPatchPrior((6, 6), b, i, c, inner=(3, 3))


def _backoff_prior(seed):
    rng = np.random.default_rng(seed)
    b = rng.integers(0, 1 << 16, 300)
    i = rng.integers(0, 512, 300)
    c = rng.integers(1, 20, 300).astype(float)
    back = rng.random(512) + 0.1
    return BackoffBorderPrior((6, 6), b, i, c, kappa=0.7, back=back, inner=(3, 3), origin=(1, 1))


@pytest.mark.parametrize("make", [_border_prior, _backoff_prior])
def test_factors_with_the_border_index_equal_the_binary_search(make):
    lp = make(0).compiled()
    assert lp.b_bits == 16 and lp.dense_bits == -1
    plain = lp._replace(b_start=np.zeros(0, np.int64), b_bits=-1)
    rng = np.random.default_rng(1)
    S = len(lp.seg_off) - 1
    seen = lp.keys[lp.seg_off[0] : lp.seg_off[1]]
    keys = np.r_[seen, seen ^ 1, rng.integers(0, 1 << 25, 3000)]  # present, near misses, mostly unseen borders
    for s in range(S):
        for key in keys.tolist():
            a = sparse_key_log_factor(lp, s, key)
            b = sparse_key_log_factor(plain, s, key)
            assert a == b or (np.isnan(a) and np.isnan(b)), (s, key, a, b)


def test_each_border_run_holds_exactly_the_keys_of_that_border():
    lp = _border_prior(2).compiled()
    s = 0
    a, b = int(lp.seg_off[s]), int(lp.seg_off[s + 1])
    borders = lp.keys[a:b] >> lp.n_inner
    for border in np.r_[np.unique(borders)[:50], np.arange(0, 1 << 16, 997)].tolist():
        lo, hi = border_range(lp.seg_off, lp.keys, lp.b_start, lp.b_bits, lp.n_inner, s, border)
        want = np.flatnonzero(borders == border) + a
        assert hi - lo == len(want)
        if len(want):
            assert lo == want[0] and hi == want[-1] + 1
