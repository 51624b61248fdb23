r"""Compiled conditionals of the stencil kind (:class:`~ogm_ppl.priors.compiled.bundles.Stencil`).

A pairwise binary field on a neighbourhood stencil (Section 5.2.1),

.. math:: \log \tilde p(m) = \sum_k m_k \Big(h_k + \sum_{d:\,k+d \in G} a_d\Big)
          + \tfrac12 \sum_k \sum_{d:\,k+d \in G} J_d\, m_k m_{k+d},

so that the conditional log-odds of a cell is affine in its neighbours,
``l(m_k | m_-k) = h_k + sum_{d: k+d in G} (a_d + J_d m_{k+d})`` (``J_d = J_{-d}``). The MRF of Section
5.2.1 is ``a_d = log psi``, ``J_d = -2 log psi``: ``l = l(lambda) + (n0 - n1) log psi``.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from ogm_ppl.priors.compiled.bundles import Stencil
from ogm_ppl.priors.compiled.registry import register

__all__ = ["stencil", "stencil_cell_log_odds", "stencil_patch_weights"]


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


@nb.njit(cache=True, inline="always")
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


@nb.njit(cache=True)
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
