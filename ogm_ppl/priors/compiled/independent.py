"""Compiled conditionals of independent cells (:class:`IndependentCells`):
``l(m_k | m_-k) = l_k``; a configuration's weight is the sum of its occupied cells' log-odds (additive)."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ogm_ppl._numba_cache import njit_shipped
from ogm_ppl.priors.compiled.registry import register
from ogm_ppl.priors.compiled.transforms import check_beta, check_bias, crop_cells, scaled, shifted

__all__ = ["IndependentCells", "independent_cells", "independent_patch_weights"]


class IndependentCells(NamedTuple):
    """Cells independent a priori: ``log p(m) = sum_k m_k l_k + const``."""

    log_odds: np.ndarray  # K float64: l_k = log lambda_k - log(1 - lambda_k)

    def sparse_patches(self) -> bool:
        """Whether patch updates may weigh a sparse support (so patches may exceed 20 cells)."""
        return False

    def patch_capacity(self, L: int) -> int:
        return max(1 << L if L <= 20 else 0, 2)

    def tempered(self, beta: float) -> IndependentCells:
        """``log p~(m)^beta = beta sum_k m_k l_k``: log-odds ``beta l_k`` (``+-inf`` kept).

        Tempering (for parallel tempering, Geyer 1991): the bundle of ``p~(m)^beta``, every log-potential
        times ``beta``; ``-inf`` (a configuration the prior forbids) stays ``-inf``. ``beta = 1`` returns
        this very bundle; ``beta = 0`` gives the uniform distribution over the prior's support (the limit
        ``beta -> 0+``). Same type, so the compiled kernels sample the tempered prior unchanged.
        """
        b = check_beta(beta)
        return self if b == 1.0 else self._replace(log_odds=scaled(self.log_odds, b))

    def biased(self, bias: float) -> IndependentCells:
        """``log p~(m) + h sum_k m_k``: log-odds ``l_k + h`` (``+-inf`` kept; :mod:`~ogm_ppl.priors.biased`)."""
        h = check_bias(bias)
        return self if h == 0.0 else self._replace(log_odds=shifted(self.log_odds, h))

    def tiles_patches(self, hw, anchors) -> bool:
        return False

    def factor_extent(self) -> int:
        """The largest extent of a factor (cells): 0, every factor is one cell."""
        return 0

    def window(self, grid_cols: int, r0: int, c0: int, rows: int, cols: int) -> IndependentCells:
        """The bundle restricted to the ``rows x cols`` window at ``(r0, c0)`` of a grid ``grid_cols`` wide."""
        return self._replace(log_odds=crop_cells(self.log_odds, grid_cols, r0, c0, rows, cols))


def independent_cells(log_odds) -> IndependentCells:
    """An :class:`IndependentCells` bundle from the ``K`` prior log-odds."""
    return IndependentCells(log_odds=np.ascontiguousarray(log_odds, dtype=np.float64))


def _cell(prior, k, m):
    return prior.log_odds[k]


@njit_shipped
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
