r"""Compiled conditionals of the stencil kind (:class:`Stencil`).

A pairwise binary field on a neighbourhood stencil (Section 5.2.1),

.. math:: \log \tilde p(m) = \sum_k m_k \Big(h_k + \sum_{d:\,k+d \in G} a_d\Big)
          + \tfrac12 \sum_k \sum_{d:\,k+d \in G} J_d\, m_k m_{k+d},

so that the conditional log-odds of a cell is affine in its neighbours,
``l(m_k | m_-k) = h_k + sum_{d: k+d in G} (a_d + J_d m_{k+d})`` (``J_d = J_{-d}``). The MRF of Section
5.2.1 is ``a_d = log psi``, ``J_d = -2 log psi``: ``l = l(lambda) + (n0 - n1) log psi``.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ogm_ppl._numba_cache import njit_shipped
from ogm_ppl.priors.compiled.registry import register
from ogm_ppl.priors.compiled.transforms import check_beta, check_bias, crop_cells, scaled, shifted

__all__ = ["Stencil", "stencil", "stencil_cell_log_odds", "stencil_patch_weights"]


class Stencil(NamedTuple):
    r"""A pairwise binary field on a stencil of offsets ``d`` (Section 5.2.1):
    ``l(m_k | m_-k) = h_k + sum_{d: k+d in G} (a_d + J_d m_{k+d})`` with ``J_d = J_{-d}``."""

    rows: int
    cols: int
    unary: np.ndarray  # K float64: h_k
    dr: np.ndarray  # D int64: the offsets
    dc: np.ndarray  # D int64
    bias: np.ndarray  # D float64: a_d
    coupling: np.ndarray  # D float64: J_d

    def sparse_patches(self) -> bool:
        return False

    def patch_capacity(self, L: int) -> int:
        return max(1 << L if L <= 20 else 0, 2)

    def tempered(self, beta: float) -> Stencil:
        """``beta h_k``, ``beta a_d``, ``beta J_d``: the conditional log-odds scale by ``beta``.

        Tempering (for parallel tempering, Geyer 1991): the bundle of ``p~(m)^beta``, every log-potential
        times ``beta``; ``-inf`` (a configuration the prior forbids) stays ``-inf``. ``beta = 1`` returns
        this very bundle; ``beta = 0`` gives the uniform distribution over the prior's support (the limit
        ``beta -> 0+``). Same type, so the compiled kernels sample the tempered prior unchanged.
        """
        b = check_beta(beta)
        if b == 1.0:
            return self
        return self._replace(unary=scaled(self.unary, b), bias=scaled(self.bias, b), coupling=scaled(self.coupling, b))

    def biased(self, bias: float) -> Stencil:
        """``log p~(m) + h sum_k m_k``: unary terms ``h_k + h`` (:mod:`~ogm_ppl.priors.biased`)."""
        h = check_bias(bias)
        return self if h == 0.0 else self._replace(unary=shifted(self.unary, h))

    def tiles_patches(self, hw, anchors) -> bool:
        return False

    def factor_extent(self) -> int:
        """The largest extent of a factor (cells): ``max(|dr|, |dc|)`` over the offsets."""
        return int(max(np.abs(self.dr).max(initial=0), np.abs(self.dc).max(initial=0)))

    def window(self, grid_cols: int, r0: int, c0: int, rows: int, cols: int) -> Stencil:
        """The bundle restricted to the ``rows x cols`` window at ``(r0, c0)`` of a grid ``grid_cols`` wide."""
        return self._replace(rows=rows, cols=cols, unary=crop_cells(self.unary, grid_cols, r0, c0, rows, cols))


def stencil(rows, cols, unary, dr, dc, bias, coupling) -> Stencil:
    """A :class:`Stencil` bundle from its weights (arrays made contiguous, of the kernels' dtypes)."""
    return Stencil(
        rows=int(rows),
        cols=int(cols),
        unary=np.ascontiguousarray(unary, np.float64),
        dr=np.ascontiguousarray(dr, np.int64),
        dc=np.ascontiguousarray(dc, np.int64),
        bias=np.ascontiguousarray(bias, np.float64),
        coupling=np.ascontiguousarray(coupling, np.float64),
    )


@njit_shipped(inline="always")
def stencil_cell_log_odds(lp, k, m):
    """``l(m_k | m_-k) = h_k + sum_{d in grid} (a_d + J_d m_{k+d})``."""
    s_dr, s_dc, s_bias, s_coup = lp.dr, lp.dc, lp.bias, lp.coupling
    rows, cols = lp.rows, lp.cols
    r = k // cols
    c = k - r * cols
    lo = lp.unary[k]
    for d in range(s_dr.shape[0]):
        rr = r + s_dr[d]
        cc = c + s_dc[d]
        if 0 <= rr < rows and 0 <= cc < cols:
            lo += s_bias[d]
            if m[rr * cols + cc]:
                lo += s_coup[d]
    return lo


@njit_shipped
def stencil_patch_weights(lp, patch, m, cands, n, out):
    """``out[j] = log p(patch = cands[j], rest)`` up to a constant in ``j`` for a stencil prior: the
    cells' fields with the patch cleared plus the couplings inside the patch. ``m`` is restored."""
    L = patch.shape[0]
    saved = np.empty(L, np.uint8)
    nl = 0
    for i in range(L):
        if patch[i] >= 0:
            saved[i] = m[patch[i]]
            m[patch[i]] = 0
            nl += 1
    field = np.empty(max(nl, 1), np.float64)
    live = np.empty(max(nl, 1), np.int64)
    b = 0
    for i in range(L):
        if patch[i] >= 0:
            field[b] = stencil_cell_log_odds(lp, patch[i], m)
            live[b] = patch[i]
            b += 1
    pi = np.empty(nl * nl, np.int64)
    pj = np.empty(nl * nl, np.int64)
    pw = np.empty(nl * nl, np.float64)
    npair = 0
    for x in range(nl):
        rx = live[x] // lp.cols
        cx = live[x] - rx * lp.cols
        for y in range(x + 1, nl):
            ry = live[y] // lp.cols
            cy = live[y] - ry * lp.cols
            for d in range(lp.dr.shape[0]):
                if ry - rx == lp.dr[d] and cy - cx == lp.dc[d]:
                    pi[npair] = x
                    pj[npair] = y
                    pw[npair] = lp.coupling[d]
                    npair += 1
    for j in range(n):
        w = cands[j]
        s = 0.0
        for x in range(nl):
            if (w >> x) & 1:
                s += field[x]
        for q in range(npair):
            if (w >> pi[q]) & 1 and (w >> pj[q]) & 1:
                s += pw[q]
        out[j] = s
    for i in range(L):
        if patch[i] >= 0:
            m[patch[i]] = saved[i]


def _cell(prior, k, m):
    return stencil_cell_log_odds(prior, k, m)


def _patch(prior, patch, m, cands, n, out, ts):
    stencil_patch_weights(prior, patch, m, cands, n, out)


def _candidates(prior, patch, m, cands, n, tag, cand_lp, out, ts):
    stencil_patch_weights(prior, patch, m, cands, n, out)


register(Stencil, cell_log_odds=_cell, patch_prior_weights=_patch, candidate_weights=_candidates)
