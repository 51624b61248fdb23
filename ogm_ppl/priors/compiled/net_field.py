r"""Compiled conditionals of the net-field kind (:class:`NetField`): a small network scored on every window, a
learned alternative to the patch tables of Section 5.2.2 whose conditionals feed the Gibbs updates of Section 4.1.

.. math:: \log \tilde p(m) = a \sum_k m_k + \sum_{(r_0, c_0)} \sum_{u < U} v_u\,
          \sigma\Big(b_u + \sum_{i, j < w} W_u[i, j]\, x_{r_0 + i,\, c_0 + j}\Big),

one term for every anchor ``(r0, c0)`` of a ``w x w`` window that holds at least one cell of the ``rows x cols``
grid (``-(w - 1) <= r0 < rows``, ``-(w - 1) <= c0 < cols``: ``(rows + w - 1) (cols + w - 1)`` windows, so every
cell lies in exactly ``w^2`` of them, at the edges too). ``x`` is the map inside the grid and the constant
``pad`` past its edge (0.5 by default: neither free nor occupied). ``sigma`` is ReLU or softplus
(:data:`ACTIVATIONS`); ``U`` hidden units with filters ``W_u`` (``w x w``), biases ``b_u`` and output weights
``v_u``; ``a`` a unary bias. (:class:`~ogm_ppl.priors.NetFieldPrior` ties the units over the 8 symmetries of the
square: its ``H`` filters in their 8 orientations, ``U = 8 H``.)

**Cell conditionals, kept by content.** The single-cell kernels call ``cell_log_odds(prior, k, m)`` with the
chain's map alone, so the bundle cannot follow a chain's flips. A cell's log-odds is

    l_k = a + sum_{windows q holding k} sum_u v_u (sigma(pre_q,u + W_u[k - q]) - sigma(pre_q,u)),

``pre_q = b + sum_{j != k} W[:, j] x_j`` the window's pre-activation with the cell cleared (``pad`` times the
column for a cell past the edge): ``w^2 (n_occ U + 2 U)`` operations afresh
(:func:`~ogm_ppl.priors.compiled.net_ops.fresh_log_odds`). The bundle keeps each cell's ``l_k`` with the content
of its ``(2w - 1)^2`` neighbourhood, and each window's ``w^2`` cell terms with the window's content
(:mod:`~ogm_ppl.priors.compiled.net_memo`): a visit whose neighbourhood is unchanged reads the kept value after
``2w - 1`` 8-byte loads, a flip makes the ``(2w - 1)^2`` cells around it and the ``w^2`` windows holding it
recompute once. Every kept value is a function of its key, so the conditionals do not depend on the chain's
history. Nothing allocates: the single-cell sweeps compile without numba's runtime.

**Patches** (:mod:`~ogm_ppl.priors.compiled.net_field_patches`): the windows a patch's live cells touch are read
once (their pre-activation with the patch cleared), and the ``2^L`` configurations are visited in Gray-code order,
each step recomputing only the windows that hold the flipped cell. Prior sampling
(:func:`~ogm_ppl.priors.compiled.net_field_patches.net_prior_sweeps`) runs the generic prior sweeps through the
memo.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ogm_ppl._numba_cache import njit_shipped
from ogm_ppl.priors.compiled.net_field_patches import net_patch_weights
from ogm_ppl.priors.compiled.net_memo import memo_arrays, memo_log_odds
from ogm_ppl.priors.compiled.net_ops import ACTIVATIONS, MAX_NET_WINDOW, MAX_UNITS
from ogm_ppl.priors.compiled.registry import register
from ogm_ppl.priors.compiled.transforms import check_beta, check_bias

__all__ = [
    "ACTIVATIONS",
    "MAX_NET_WINDOW",
    "MAX_UNITS",
    "NetField",
    "net_cell_log_odds",
    "net_field",
]


class NetField(NamedTuple):
    r"""A network scored on every ``w x w`` window meeting the grid (module docstring): ``log p~(m) = a sum_k m_k
    + sum_windows sum_u v_u sigma(b_u + <W_u, x_window>)``, cells past the edge read as ``pad``."""

    rows: int
    cols: int
    w: int  # window side
    units: int  # U hidden units
    act: int  # index into ACTIVATIONS
    pad: float  # the value of a cell past the grid's edge
    unary: float  # a: log-odds added to every cell
    wt: np.ndarray  # w*w*U float64: wt[p U + u] = W_u[p // w, p % w] (one column of U weights per window cell)
    wt_t: np.ndarray  # U*w*w float64: wt_t[u w^2 + p] = W_u[p // w, p % w] (the weights unit-major)
    bias: np.ndarray  # U float64
    out: np.ndarray  # U float64: v_u
    kw: int  # int64 words of a neighbourhood key (key_words(w))
    memo_key: np.ndarray  # rows*cols*kw int64: the neighbourhood key of each cell's memoised log-odds (0: none)
    memo_lo: np.ndarray  # rows*cols float64: each cell's log-odds at its memoised key
    win_key: np.ndarray  # (rows+w-1)*(cols+w-1) int64: each window anchor's memoised content (w <= 7; else empty)
    win_delta: np.ndarray  # (rows+w-1)*(cols+w-1)*w*w float64: each window's memoised cell terms

    def cache_fields(self) -> tuple[str, ...]:
        """The fields that are caches the sweeps fill, not of the distribution (a checkpoint's fingerprint
        reads them as empty)."""
        return ("memo_key", "memo_lo", "win_key", "win_delta")

    def sparse_patches(self) -> bool:
        return False

    def patch_capacity(self, L: int) -> int:
        return max(1 << L if L <= 20 else 0, 2)

    def tiles_patches(self, hw, anchors) -> bool:
        return False

    def tempered(self, beta: float) -> NetField:
        """The bundle of ``beta log p~``: output weights and unary bias times ``beta``."""
        b = check_beta(beta)
        return self._replace(out=self.out * b, unary=self.unary * b, **_memo(self.rows, self.cols, self.w))

    def biased(self, bias: float) -> NetField:
        """The bundle of ``log p~ + h sum_k m_k``: unary bias plus ``h``."""
        return self._replace(unary=self.unary + check_bias(bias), **_memo(self.rows, self.cols, self.w))

    def factor_extent(self) -> int:
        """The largest extent of a factor (cells): ``w - 1`` (a window)."""
        return self.w - 1

    def window(self, grid_cols: int, r0: int, c0: int, rows: int, cols: int) -> NetField:
        """The bundle on the ``rows x cols`` window at ``(r0, c0)``: a cell whose windows all lie in it (at least
        ``w - 1`` cells from its edges, or at the grid's own edge) has the same conditional."""
        return self._replace(rows=int(rows), cols=int(cols), **_memo(rows, cols, self.w))


def _memo(rows: int, cols: int, w: int) -> dict:
    return memo_arrays(rows, cols, w)


def net_field(rows: int, cols: int, filters, bias, out, unary: float = 0.0, pad: float = 0.5, activation="relu"):
    """A :class:`NetField` bundle from the units' ``filters`` (``U x w x w``), ``bias`` and ``out`` (``U``)."""
    f = np.asarray(filters, np.float64)
    if f.ndim != 3 or f.shape[1] != f.shape[2]:
        raise ValueError(f"filters must be U x w x w, got shape {f.shape}")
    U, w = f.shape[0], f.shape[1]
    if not 1 <= w <= MAX_NET_WINDOW:
        raise ValueError(f"net field window side must lie in 1..{MAX_NET_WINDOW}, got {w}")
    if not 1 <= U <= MAX_UNITS:
        raise ValueError(f"a net field has 1..{MAX_UNITS} hidden units, got {U}")
    b = np.ascontiguousarray(bias, np.float64).reshape(-1)
    v = np.ascontiguousarray(out, np.float64).reshape(-1)
    if b.shape != (U,) or v.shape != (U,):
        raise ValueError(f"bias and out must hold U = {U} values, got {b.shape} and {v.shape}")
    if activation not in ACTIVATIONS:
        raise ValueError(f"activation must be one of {ACTIVATIONS}, got {activation!r}")
    vals = (f, b, v, np.array([unary, pad], np.float64))
    if not all(np.isfinite(x).all() for x in vals):
        raise ValueError("net field weights, unary and pad must be finite (the field is strictly positive)")
    return NetField(
        rows=int(rows),
        cols=int(cols),
        w=int(w),
        units=int(U),
        act=ACTIVATIONS.index(activation),
        pad=float(pad),
        unary=float(unary),
        wt=np.ascontiguousarray(f.reshape(U, w * w).T.reshape(-1)),
        wt_t=np.ascontiguousarray(f.reshape(-1)),
        bias=b,
        out=v,
        **_memo(rows, cols, w),
    )


# ------------------------------------------------------------------ single cells
@njit_shipped(inline="always")
def net_cell_log_odds(nf, k, m):
    """``log p~(m_k = 1, m_-k) - log p~(m_k = 0, m_-k)`` of a net field, through the bundle's memo
    (:func:`~ogm_ppl.priors.compiled.net_memo.memo_log_odds`). Allocates nothing."""
    return memo_log_odds(nf, k, m)


def _cell(prior, k, m):
    return net_cell_log_odds(prior, k, m)


def _patch(prior, patch, m, cands, n, out, ts):
    net_patch_weights(prior, patch, m, cands, n, out, ts)


def _candidates(prior, patch, m, cands, n, tag, cand_lp, out, ts):
    net_patch_weights(prior, patch, m, cands, n, out, ts)


register(NetField, cell_log_odds=_cell, patch_prior_weights=_patch, candidate_weights=_candidates)
