"""Compiled conditionals of independent cells (:class:`~ogm_ppl.priors.compiled.bundles.IndependentCells`):
``l(m_k | m_-k) = l_k``; a configuration's weight is the sum of its occupied cells' log-odds (additive)."""

from __future__ import annotations

import numba as nb
import numpy as np

from ogm_ppl.priors.compiled.bundles import IndependentCells
from ogm_ppl.priors.compiled.registry import register

__all__ = ["independent_cells", "independent_patch_weights"]


def independent_cells(log_odds) -> IndependentCells:
    """An :class:`IndependentCells` bundle from the ``K`` prior log-odds."""
    return IndependentCells(log_odds=np.ascontiguousarray(log_odds, dtype=np.float64))


def _cell(prior, k, m):
    return prior.log_odds[k]


@nb.njit(cache=True)
def independent_patch_weights(prior, patch, m, cands, n, out):
    """``out[j] = sum of l_c over the live cells c of patch that cands[j] sets``."""
    lo = prior.log_odds
    for j in range(n):
        w = cands[j]
        s = 0.0
        b = 0
        for i in range(patch.shape[0]):
            c = patch[i]
            if c < 0:
                continue
            if (w >> b) & 1:
                s += lo[c]
            b += 1
        out[j] = s


def _patch(prior, patch, m, cands, n, out, ts):
    independent_patch_weights(prior, patch, m, cands, n, out)


def _candidates(prior, patch, m, cands, n, tag, cand_lp, out, ts):
    independent_patch_weights(prior, patch, m, cands, n, out)


register(
    IndependentCells, cell_log_odds=_cell, patch_prior_weights=_patch, candidate_weights=_candidates, additive=True
)
