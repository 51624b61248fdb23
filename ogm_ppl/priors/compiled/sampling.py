"""Compiled batch passes over maps that any bundle kind runs through its registered conditionals: Gibbs
sweeps on the prior alone (prior sampling), the patch weights of a batch of maps (``log_prob_patch``) and the
held-out negative log conditionals of a map's cells (a pseudo-likelihood score any kind can be compared by)."""

from __future__ import annotations

import numpy as np

from ogm_ppl._numba_cache import njit_shipped
from ogm_ppl.priors.compiled.registry import cell_log_odds, patch_prior_weights, scratch_capacity
from ogm_ppl.priors.compiled.scratch import tile_scratch

__all__ = ["conditional_nll", "patch_prior_batch", "prior_gibbs_sweeps"]


@njit_shipped
def prior_gibbs_sweeps(prior, maps, num_sweeps, seed):
    """Single-cell Gibbs sweeps on the prior alone, for each row of ``maps`` (``B x K`` uint8), in place."""
    np.random.seed(seed)
    for b in range(maps.shape[0]):
        m = maps[b]
        for _ in range(num_sweeps):
            for k in range(m.shape[0]):
                lo = cell_log_odds(prior, k, m)
                if lo != lo:
                    continue
                u = np.random.random()
                if lo >= 0:
                    m[k] = 1 if u * (1.0 + np.exp(-lo)) < 1.0 else 0
                else:
                    e = np.exp(lo)
                    m[k] = 1 if u * (1.0 + e) < e else 0


@njit_shipped
def patch_prior_batch(prior, maps, patch, cands, out):
    """``out[b, j] = log p(patch = cands[j], rest of maps[b])`` up to a constant in ``j`` (``B x K`` uint8
    maps; bit ``i`` of a candidate = the ``i``-th live cell of ``patch``)."""
    ts = tile_scratch(maps.shape[1], np.int64(scratch_capacity(prior, patch.shape[0])))
    for b in range(maps.shape[0]):
        patch_prior_weights(prior, patch, maps[b], cands, cands.shape[0], out[b], ts)


@njit_shipped
def conditional_nll(prior, m, cells):
    """``sum_k -log p(m_k | m_-k)`` over ``cells`` (int64 grid ids) of the map ``m`` (``K`` uint8), by the bundle's
    compiled cell log-odds ``l``: ``softplus(-l)`` for an occupied cell, ``softplus(l)`` for a free one (a cell whose
    log-odds are ``nan``, a map without mass either way, counts ``log 2``)."""
    tot = 0.0
    for i in range(cells.shape[0]):
        k = cells[i]
        lo = cell_log_odds(prior, k, m)
        if lo != lo:
            tot += np.log(2.0)
            continue
        x = -lo if m[k] else lo
        tot += max(x, 0.0) + np.log1p(np.exp(-abs(x)))
    return tot
