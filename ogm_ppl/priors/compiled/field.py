r"""Compiled conditionals of the pattern-field kind (:class:`PatternField`).

A strictly positive, translation-invariant field of patterns (Felzenszwalb & Oberlin, multiscale fields of
patterns, NeurIPS 2014), a learned alternative to the patch tables of Section 5.2.2:

.. math:: \log \tilde p(m) = \sum_{(r, c)} \theta\big[\mathrm{code}(m_{r:r+w,\, c:c+w})\big]
          + \sum_{(i, j)} \theta_2\big[\mathrm{code}(\bar m_{i:i+w,\, j:j+w})\big],

the first sum over every anchor of a ``w x w`` window wholly inside the ``rows x cols`` grid, the second
(two scales only) over the windows wholly inside the *pooled* grid ``\bar m``. Codes follow the package's
convention (row-major, little-endian: window cell ``a w + b`` is bit ``a w + b``).

**The pooled grid.** ``\bar m`` has ``ceil(rows / 2) x ceil(cols / 2)`` cells; pooled cell ``(i, j)`` is
the OR of the cells ``{2i, 2i + 1} x {2j, 2j + 1}`` that lie inside the grid. At an odd size the last
pooled row (column) pools a ``1 x 2`` (``2 x 1``) block, and the corner a single cell: cells past the
edge read as free, never as occupied.

**Conditionals.** A cell's log-odds is ``sum_windows theta[base | bit] - theta[base]`` over the (at most
``w^2``) windows holding it, ``base`` its code with the cell cleared; the cell's ``(2w - 1)^2``
neighbourhood is read once into one integer and each window's code is cut from it by shifts. For ``w = 3``
away from the edges the neighbourhood is five unaligned 8-byte loads (one a row, its 0/1 bytes gathered
into bits by one multiplication) and the nine windows' terms are three entries of a row-block table
(:func:`_delta_table`). At scale 2
the flip changes the pooled parent only when the other cells of its ``2 x 2`` block are free; then the
pooled windows holding the parent add their terms the same way. A patch update reads, once, each window
its live cells touch (base code with the patch cleared, and the (patch bit, window bit) pairs by which
a candidate sets bits in it); a candidate then scatters its bits into those codes only. When all ``2^L``
configurations of a full rectangular patch are weighed (a patch Gibbs update), the windows are summed by
row groups instead (:func:`_rect_window_sums`): the windows whose rows meet the same patch rows depend on
a configuration only through those rows' bits, so each group is one small table and a configuration
adds one entry per group.
"""

from __future__ import annotations

from typing import NamedTuple

import numba as nb
import numpy as np
from llvmlite import ir
from numba.core import cgutils, types
from numba.extending import intrinsic

from ogm_ppl._numba_cache import njit_shipped
from ogm_ppl.priors.compiled.field_patches import _pooled, field_patch_weights
from ogm_ppl.priors.compiled.registry import register

__all__ = [
    "MAX_WINDOW",
    "field_cell_log_odds",
    "field_log_prob_batch",
    "field_patch_weights",
    "field_window_codes",
    "pattern_field",
]

#: the largest window side (``w^2 <= 16`` bits: the neighbourhood of a cell, ``(2w - 1)^2`` bits, fits an int64)
MAX_WINDOW = 4


class PatternField(NamedTuple):
    r"""A translation-invariant field of ``w x w`` patterns, optionally at two scales:
    ``log p~(m) = sum_windows theta[code] + sum_pooled windows theta2[code]`` (see
    :mod:`~ogm_ppl.priors.compiled.field` for the codes and the pooled grid)."""

    rows: int
    cols: int
    w: int  # window side
    n_scales: int  # 1 or 2
    prow: int  # pooled grid: ceil(rows / 2) x ceil(cols / 2)
    pcol: int
    theta: np.ndarray  # 2^(w w) float64: log-potential of each window code at scale 1
    theta2: np.ndarray  # 2^(w w) float64: the same at scale 2 (zeros when n_scales == 1)
    # w = 3: delta[a << 15 | block] = the log-odds terms of the three windows anchored on row a of a cell's
    # 5 x 5 neighbourhood, block = its rows a .. a + 2 (field._delta_table); three loads a cell; else empty
    delta: np.ndarray
    delta2: np.ndarray

    def sparse_patches(self) -> bool:
        return False

    def patch_capacity(self, L: int) -> int:
        return max(1 << L if L <= 20 else 0, 2)

    def tiles_patches(self, hw, anchors) -> bool:
        return False

    def tempered(self, beta: float) -> PatternField:
        """The bundle of ``beta * log p~`` (every log-potential times ``beta``)."""
        b = float(beta)
        return self._replace(theta=self.theta * b, theta2=self.theta2 * b, delta=self.delta * b, delta2=self.delta2 * b)

    def factor_extent(self) -> int:
        """The largest extent of a factor (cells): ``w - 1``, or ``2 w - 1`` with the pooled scale."""
        return 2 * self.w - 1 if self.n_scales == 2 else self.w - 1

    def window(self, grid_cols: int, r0: int, c0: int, rows: int, cols: int) -> PatternField:
        """The bundle on the ``rows x cols`` window at ``(r0, c0)`` (``r0``, ``c0`` even: the pooled pairs)."""
        if r0 % 2 or c0 % 2:
            raise ValueError(f"a pattern field's window must start at an even row and column, got ({r0}, {c0})")
        return self._replace(rows=rows, cols=cols, prow=(rows + 1) // 2, pcol=(cols + 1) // 2)


def pattern_field(rows: int, cols: int, w: int, theta, theta2=None) -> PatternField:
    """A :class:`PatternField` bundle: ``theta`` (and ``theta2`` for two scales) dense tables of
    ``2^(w w)`` finite log-potentials."""
    w = int(w)
    if not 1 <= w <= MAX_WINDOW:
        raise ValueError(f"pattern field window side must lie in 1..{MAX_WINDOW}, got {w}")
    n = 1 << (w * w)
    t1 = np.ascontiguousarray(theta, np.float64).reshape(-1)
    if t1.shape != (n,):
        raise ValueError(f"theta must have 2^(w w) = {n} entries, got {t1.shape}")
    t2 = np.zeros(n) if theta2 is None else np.ascontiguousarray(theta2, np.float64).reshape(-1)
    if t2.shape != (n,):
        raise ValueError(f"theta2 must have 2^(w w) = {n} entries, got {t2.shape}")
    if not (np.isfinite(t1).all() and np.isfinite(t2).all()):
        raise ValueError("pattern field log-potentials must be finite (the field is strictly positive)")
    return PatternField(
        delta=_delta_table(t1, w),
        delta2=_delta_table(t2, w),
        rows=int(rows),
        cols=int(cols),
        w=w,
        n_scales=1 if theta2 is None else 2,
        prow=(int(rows) + 1) // 2,
        pcol=(int(cols) + 1) // 2,
        theta=t1,
        theta2=np.ascontiguousarray(t2),
    )


def _delta_table(theta: np.ndarray, w: int) -> np.ndarray:
    """``w = 3``: the row-block table of a cell's log-odds, ``3 x 2^15`` float64 flattened. A cell's ``5 x 5``
    neighbourhood (25 bits, row-major, :func:`_nbhd3`) holds three blocks of three rows, ``block_a =
    (nbhd >> 5 a) & 0x7FFF`` (``a = 0, 1, 2``); block ``a`` holds the three windows anchored on its first row
    (window ``(a, b)`` reads block bits ``5 i + b + j``, ``i, j < 3``) and the cell at block bit ``12 - 5 a``
    (cleared in ``nbhd``). Entry ``a << 15 | block`` is ``sum_b theta[code_ab | bit] - theta[code_ab]`` (the
    cell is bit ``(2 - a) 3 + 2 - b`` of window ``(a, b)``), so a cell's log-odds is three loads. Entries
    with the cell's bit set are never read. Else (``w != 3``) empty."""
    if w != 3:
        return np.zeros(0)
    block = np.arange(1 << 15, dtype=np.int64)
    out = np.zeros((3, 1 << 15))
    for a in range(3):
        for b in range(3):
            code = np.zeros_like(block)
            for i in range(3):
                code |= ((block >> (5 * i + b)) & 7) << (3 * i)
            bit = 1 << ((2 - a) * 3 + 2 - b)
            out[a] += theta[code | bit] - theta[code & ~bit]
    return np.ascontiguousarray(out.ravel())


# ------------------------------------------------------------------ single cells
@nb.njit(cache=True, inline="always")
def _window_delta(theta, w, R, C, r, c, nbhd):
    """``sum theta[base | bit] - theta[base]`` over the windows of an ``R x C`` grid holding ``(r, c)``;
    ``nbhd`` holds the cell's neighbourhood, bit ``(i - r + w - 1) S + (j - c + w - 1)`` (``S = 2w - 1``) =
    cell ``(i, j)``, with ``(r, c)`` itself cleared."""
    S = 2 * w - 1
    wmask = (np.int64(1) << w) - 1
    lo = 0.0
    for r0 in range(max(0, r - w + 1), min(r, R - w) + 1):
        for c0 in range(max(0, c - w + 1), min(c, C - w) + 1):
            sh = (r0 - r + w - 1) * S + (c0 - c + w - 1)
            code = np.int64(0)
            for a in range(w):
                code |= ((nbhd >> (sh + a * S)) & wmask) << (a * w)
            bit = np.int64(1) << ((r - r0) * w + (c - c0))
            lo += theta[code | bit] - theta[code]
    return lo


@nb.njit(cache=True, inline="always")
def _delta3(delta, nbhd):
    """:func:`_window_delta` of an interior cell and ``w = 3`` from the row-block table (three loads, one a
    block of three neighbourhood rows, :func:`_delta_table`)."""
    return (
        delta[nbhd & 0x7FFF]
        + delta[(np.int64(1) << 15) | ((nbhd >> 5) & 0x7FFF)]
        + delta[(np.int64(2) << 15) | ((nbhd >> 10) & 0x7FFF)]
    )


@intrinsic
def _load8(typingctx, m, k):
    """The 8 bytes ``m[k : k + 8]`` of a C-contiguous uint8 array as one little-endian int64 (an unaligned
    load; the caller keeps ``k + 8 <= len(m)``)."""
    if not (isinstance(m, types.Array) and m.dtype == types.uint8 and m.ndim == 1 and m.layout == "C"):
        return None

    def codegen(context, builder, signature, args):
        ary = context.make_array(signature.args[0])(context, builder, args[0])
        ptr = cgutils.get_item_pointer(context, builder, signature.args[0], ary, [args[1]])
        return builder.load(builder.bitcast(ptr, ir.IntType(64).as_pointer()), align=1)

    return types.int64(m, types.intp), codegen


#: gathers the low bits of 0/1 bytes 0..4 of a word to bits 56..60 (the partial products never collide)
_GATHER5 = np.int64(0x0102040810204080)
#: gathers the low bits of 0/1 bytes 0, 2, 4, 6 of a word to bits 56..59
_GATHER_EVEN = np.int64((1 << 56) | (1 << 41) | (1 << 26) | (1 << 11))


@nb.njit(cache=True, inline="always")
def _row5(m, k):
    """Cells ``m[k : k + 5]`` (each 0 or 1) as 5 bits, cell ``k + b`` at bit ``b``."""
    return (((_load8(m, k) & 0xFFFFFFFFFF) * _GATHER5) >> 56) & 31


@nb.njit(cache=True, inline="always")
def _nbhd3(m, cols, k):
    """The ``5 x 5`` neighbourhood of the interior cell ``k`` as 25 bits (row-major: bit ``5 a + b`` = cell
    ``k + (a - 2) cols + b - 2``), the cell itself cleared: five 8-byte loads (the caller keeps
    ``k + 2 cols + 6 <= len(m)``)."""
    k0 = k - 2 * cols - 2
    return (
        _row5(m, k0)
        | (_row5(m, k0 + cols) << 5)
        | ((_row5(m, k0 + 2 * cols) & 27) << 10)
        | (_row5(m, k0 + 3 * cols) << 15)
        | (_row5(m, k0 + 4 * cols) << 20)
    )


@nb.njit(cache=True, inline="always")
def _pooled_row5(m, cols, k):
    """Pooled cells ``0 .. 4`` of the pooled row whose blocks start at cell ``k`` (rows ``k``, ``k + cols``,
    columns ``k .. k + 9``) as 5 bits: four 8-byte loads."""
    z = _load8(m, k) | _load8(m, k + cols)
    z = z | (z >> 8)  # byte 2 j: pooled cell j (j < 4)
    t = _load8(m, k + 2) | _load8(m, k + 2 + cols)
    t = (t | (t >> 8)) >> 48  # bytes 8, 9 of the row pair: pooled cell 4
    return ((((z & 0x0001000100010001) * _GATHER_EVEN) >> 56) & 15) | ((t & 1) << 4)


@nb.njit(cache=True, inline="always")
def _pooled_nbhd3(m, cols, pr, pc):
    """The pooled ``5 x 5`` neighbourhood of an interior pooled cell ``(pr, pc)`` (parent cleared); the
    cells of the pooled blocks all lie in the grid (pooled rows / columns ``<= pr + 2`` below the last)."""
    k = 2 * (pr - 2) * cols + 2 * (pc - 2)
    return (
        _pooled_row5(m, cols, k)
        | (_pooled_row5(m, cols, k + 2 * cols) << 5)
        | ((_pooled_row5(m, cols, k + 4 * cols) & 27) << 10)
        | (_pooled_row5(m, cols, k + 6 * cols) << 15)
        | (_pooled_row5(m, cols, k + 8 * cols) << 20)
    )


@njit_shipped
def _edge_scale1(lp, r, c, m):
    """Scale-1 log-odds of a cell near the edge (or ``w != 3``). (Not inlined: a large inlined body slows
    the loops around it, and edge cells are few.)"""
    rows, cols, w = lp.rows, lp.cols, lp.w
    S = 2 * w - 1
    nbhd = np.int64(0)
    for i in range(max(0, r - w + 1), min(rows, r + w)):
        base = (i - r + w - 1) * S - c + w - 1
        for j in range(max(0, c - w + 1), min(cols, c + w)):
            if m[i * cols + j]:
                nbhd |= np.int64(1) << (base + j)
    nbhd &= ~(np.int64(1) << ((w - 1) * S + w - 1))
    return _window_delta(lp.theta, w, rows, cols, r, c, nbhd)


@njit_shipped
def _edge_scale2(lp, pr, pc, m):
    """Scale-2 log-odds of a flip that changes the parent ``(pr, pc)`` near the pooled grid's edge."""
    rows, cols, w = lp.rows, lp.cols, lp.w
    P, Q = lp.prow, lp.pcol
    S = 2 * w - 1
    pn = np.int64(0)
    for i in range(max(0, pr - w + 1), min(P, pr + w)):
        base = (i - pr + w - 1) * S - pc + w - 1
        for j in range(max(0, pc - w + 1), min(Q, pc + w)):
            if (i != pr or j != pc) and _pooled(m, rows, cols, i, j):
                pn |= np.int64(1) << (base + j)
    return _window_delta(lp.theta2, w, P, Q, pr, pc, pn)


@njit_shipped(inline="always")
def field_cell_log_odds(lp, k, m):
    """``log p~(m_k = 1, m_-k) - log p~(m_k = 0, m_-k)`` of a pattern field (``w = 3`` cells away from
    the edges read their neighbourhood in five word loads and sum three row-block entries; the others
    :func:`_edge_scale1`)."""
    rows, cols = lp.rows, lp.cols
    fast = lp.w == 3
    r = k // cols
    c = k - r * cols
    if fast and 2 <= r < rows - 2 and 2 <= c < cols - 2 and k + 2 * cols + 6 <= m.shape[0]:
        lo = _delta3(lp.delta, _nbhd3(m, cols, k))
    else:
        lo = _edge_scale1(lp, r, c, m)
    if lp.n_scales == 2:
        pr = r >> 1
        pc = c >> 1
        # the parent changes with m_k only if the rest of its block is free
        b = 2 * pr * cols + 2 * pc
        if 2 * pr + 1 < rows and 2 * pc + 1 < cols:
            others = np.int64(m[b]) + m[b + 1] + m[b + cols] + m[b + cols + 1] - m[k]
        else:
            others = np.int64(0)
            for i in range(2 * pr, min(2 * pr + 2, rows)):
                for j in range(2 * pc, min(2 * pc + 2, cols)):
                    if (i != r or j != c) and m[i * cols + j]:
                        others = 1
        if others == 0:
            # interior: the pooled 5 x 5 inside the pooled grid, and its blocks whole (2 (pr + 2) + 1 < rows)
            if fast and 2 <= pr and 2 * pr + 5 < rows and 2 <= pc and 2 * pc + 5 < cols:
                lo += _delta3(lp.delta2, _pooled_nbhd3(m, cols, pr, pc))
            else:
                lo += _edge_scale2(lp, pr, pc, m)
    return lo


# ------------------------------------------------------------------ patches
@nb.njit(cache=True)
def field_window_codes(grid, w):
    """The code of every ``w x w`` window of an ``R x C`` uint8 grid: ``(R - w + 1) x (C - w + 1)`` int64
    (empty when the grid is smaller than the window)."""
    R, C = grid.shape
    nr = max(R - w + 1, 0)
    nc = max(C - w + 1, 0)
    out = np.zeros((nr, nc), np.int64)
    for r0 in range(nr):
        for c0 in range(nc):
            code = np.int64(0)
            for a in range(w):
                for b in range(w):
                    if grid[r0 + a, c0 + b]:
                        code |= np.int64(1) << (a * w + b)
            out[r0, c0] = code
    return out


@njit_shipped
def field_log_prob_batch(lp, maps, out):
    """``log p~(m)`` for every row of ``maps`` (``B x K`` uint8)."""
    rows, cols, w = lp.rows, lp.cols, lp.w
    P, Q = lp.prow, lp.pcol
    for bi in range(maps.shape[0]):
        m = maps[bi]
        g = m.reshape(rows, cols)
        s = 0.0
        codes = field_window_codes(g, w)
        for r0 in range(codes.shape[0]):
            for c0 in range(codes.shape[1]):
                s += lp.theta[codes[r0, c0]]
        if lp.n_scales == 2:
            pg = np.zeros((P, Q), np.uint8)
            for i in range(P):
                for j in range(Q):
                    pg[i, j] = _pooled(m, rows, cols, i, j)
            codes = field_window_codes(pg, w)
            for r0 in range(codes.shape[0]):
                for c0 in range(codes.shape[1]):
                    s += lp.theta2[codes[r0, c0]]
        out[bi] = s


def _cell(prior, k, m):
    return field_cell_log_odds(prior, k, m)


def _patch(prior, patch, m, cands, n, out, ts):
    field_patch_weights(prior, patch, m, cands, n, out, ts)


def _candidates(prior, patch, m, cands, n, tag, cand_lp, out, ts):
    field_patch_weights(prior, patch, m, cands, n, out, ts)


register(PatternField, cell_log_odds=_cell, patch_prior_weights=_patch, candidate_weights=_candidates)
