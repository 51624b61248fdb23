r"""Compiled conditionals of the pattern-field kind (:class:`~ogm_ppl.priors.compiled.bundles.PatternField`).

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

import numba as nb
import numpy as np
from llvmlite import ir
from numba.core import cgutils, types
from numba.extending import intrinsic

from ogm_ppl.priors.compiled.bundles import PatternField
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
def _pooled(m, rows, cols, i, j):
    """Pooled cell ``(i, j)``: OR of the in-grid cells of the block ``{2i, 2i+1} x {2j, 2j+1}``."""
    r = 2 * i
    c = 2 * j
    k = r * cols + c
    v = m[k]
    if c + 1 < cols:
        v |= m[k + 1]
    if r + 1 < rows:
        v |= m[k + cols]
        if c + 1 < cols:
            v |= m[k + cols + 1]
    return v


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


@nb.njit(cache=True)
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


@nb.njit(cache=True)
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


@nb.njit(cache=True, inline="always")
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
def _scale_setup(w, R, C, cells_r, cells_c, n_live, is_live, value, o_r, o_c, S, anchors, base, pr_off, pr_pb, pr_wb):
    """The windows of an ``R x C`` grid holding one of the ``n_live`` live cells ``(cells_r, cells_c)``:
    per window its code with the live cells cleared (``base``; other cells read from the 0/1 array
    ``value``) and the pairs (live index, window bit). ``is_live``: live index or -1. Both arrays hold cell
    ``(i, j)`` at ``(i - o_r) S + j - o_c`` (the whole grid: ``0, 0, C``; or a box around the live cells
    that holds every window's cells). Returns the number of windows."""
    nw = 0
    npair = 0
    pr_off[0] = 0
    for x in range(n_live):
        r = cells_r[x]
        c = cells_c[x]
        for r0 in range(max(0, r - w + 1), min(r, R - w) + 1):
            for c0 in range(max(0, c - w + 1), min(c, C - w) + 1):
                # a window is owned by the first live cell it holds: skip it if an earlier one is inside
                first = True
                for a in range(w):
                    for b in range(w):
                        q = is_live[(r0 + a - o_r) * S + c0 + b - o_c]
                        if q >= 0 and q < x:
                            first = False
                if not first:
                    continue
                code = np.int64(0)
                for a in range(w):
                    for b in range(w):
                        kk = (r0 + a - o_r) * S + c0 + b - o_c
                        q = is_live[kk]
                        if q >= 0:
                            pr_pb[npair] = q
                            pr_wb[npair] = a * w + b
                            npair += 1
                        elif value[kk]:
                            code |= np.int64(1) << (a * w + b)
                anchors[nw] = r0 * C + c0
                base[nw] = code
                nw += 1
                pr_off[nw] = npair
    return nw


@nb.njit(cache=True)
def _window_sums(theta, nw, base, pr_off, pr_pb, pr_wb, cands, n, out, add):
    """``out[j] = sum_q theta[code_q(cands[j])]`` over the windows of :func:`_scale_setup`, each
    candidate's bits placed into every window code (``add``: added to ``out[j]``, term by term)."""
    for jx in range(n):
        cand = cands[jx]
        s = out[jx] if add else 0.0
        for q in range(nw):
            code = base[q]
            for p in range(pr_off[q], pr_off[q + 1]):
                code |= ((cand >> pr_pb[p]) & 1) << pr_wb[p]
            s += theta[code]
        out[jx] = s


#: the pooled scale's sums are tabled over the parents' configurations for patches of at most this many parents
POOLED_TABLE_BITS = 10

#: recompute the Gray-code running sum from the window codes every this many steps (bounds the rounding)
GRAY_RESYNC = 64


@nb.njit(cache=True)
def _window_sums_gray(theta, nw, base, pr_off, pr_pb, pr_wb, nl, out):
    """:func:`_window_sums` for the ``2^nl`` candidates ``0 .. 2^nl - 1`` in order, visited in Gray-code
    order: step ``i`` flips live bit ``ctz(i)``, which changes only the windows holding that cell (9 of the 25
    of a 3 x 3 patch under 3 x 3 windows), so the sum moves by their ``theta`` differences; it is summed afresh
    every :data:`GRAY_RESYNC` steps. Equal to :func:`_window_sums` to rounding (a few ulp of the sums)."""
    # per live bit: the (window, window-bit mask) pairs it enters
    cnt = np.zeros(nl + 1, np.int64)
    for p in range(pr_off[nw]):
        cnt[pr_pb[p] + 1] += 1
    for x in range(nl):
        cnt[x + 1] += cnt[x]
    fill = cnt[:nl].copy()
    xq = np.empty(max(pr_off[nw], 1), np.int64)
    xm = np.empty(max(pr_off[nw], 1), np.int64)
    for q in range(nw):
        for p in range(pr_off[q], pr_off[q + 1]):
            x = pr_pb[p]
            xq[fill[x]] = q
            xm[fill[x]] = np.int64(1) << pr_wb[p]
            fill[x] += 1
    code = base[:nw].copy()
    s = 0.0
    for q in range(nw):
        s += theta[code[q]]
    out[0] = s
    g = np.int64(0)
    for i in range(1, np.int64(1) << nl):
        x = 0
        while not (i >> x) & 1:
            x += 1
        g ^= np.int64(1) << x
        if i % GRAY_RESYNC == 0:
            for e in range(cnt[x], cnt[x + 1]):
                code[xq[e]] ^= xm[e]
            s = 0.0
            for q in range(nw):
                s += theta[code[q]]
        else:
            for e in range(cnt[x], cnt[x + 1]):
                q = xq[e]
                old = theta[code[q]]
                code[q] ^= xm[e]
                s += theta[code[q]] - old
        out[g] = s


@nb.njit(cache=True, inline="always")
def _rect_shape(patch, cols):
    """``(ph, pw)`` when the cells of ``patch`` are every cell of an ``ph x pw`` rectangle of the grid, in
    row-major order (none cut off or pinned); else ``(0, 0)``."""
    L = patch.shape[0]
    k0 = patch[0]
    if k0 < 0:
        return 0, 0
    c0 = k0 % cols
    pw = 1
    while pw < L and c0 + pw < cols and patch[pw] == k0 + pw:
        pw += 1
    ph = L // pw
    if ph * pw != L:
        return 0, 0
    for i in range(L):
        a = i // pw
        if patch[i] != k0 + a * cols + (i - a * pw):
            return 0, 0
    return ph, pw


@nb.njit(cache=True, inline="always")
def _rect_fits(w, ph, pw, room):
    """Whether a row group's table of :func:`_rect_window_sums` (at most ``min(w, ph)`` patch rows) fits
    ``room``."""
    k = min(w, ph) * pw
    return ph > 0 and k <= 20 and (np.int64(1) << k) <= room


@nb.njit(cache=True, inline="always")
def _rect_window_sums(theta, w, m, rows, cols, r0, c0, ph, pw, out, T, P):
    r"""``out[c] = sum_q theta[code_q(c)]`` for every configuration ``c < 2^(ph pw)`` of the full
    ``ph x pw`` patch at ``(r0, c0)`` (bit ``a pw + b``: patch cell ``(a, b)``), over the ``w x w`` windows
    inside the grid that hold a patch cell. A window whose top row is ``a`` rows below the patch's holds the
    patch rows ``max(a, 0) .. min(a + w - 1, ph - 1)``, a contiguous run of ``k`` bits of ``c``: the windows
    of one ``a`` (a row group) are summed into one table ``T`` over the run's ``2^k`` configurations ``s``,
    and ``c`` adds one entry of each group's table. A window's code of ``s`` is its code with the patch
    cleared, OR the placement of the run's first patch row (``2^pw`` entries) and of its other rows
    (``2^(k - pw)``), two small tables built per window (in ``P``). A ``3 x 3`` patch under ``3 x 3`` windows:
    five groups of five windows, tables of 8, 64, 512, 64 and 8 entries, then five reads per configuration.
    ``T``: room for ``2^k`` of the largest group (float64); ``P``: for ``2^pw + 2^(k - pw)`` codes (int64)."""
    n = np.int64(1) << (ph * pw)
    for c in range(n):
        out[c] = 0.0
    wmask = (np.int64(1) << w) - 1
    pmask = (np.int64(1) << pw) - 1
    for a in range(1 - w, ph):
        R = r0 + a
        if R < 0 or R + w > rows:
            continue
        ra = max(a, 0)
        nr = min(a + w - 1, ph - 1) - ra + 1
        nk = np.int64(1) << (nr * pw)
        n_lo = np.int64(1) << pw
        n_hi = nk >> pw
        into = ra == 0 and nk == n  # the group spans every patch bit: sum straight into out
        if not into:
            for s in range(nk):
                T[s] = 0.0
        for b in range(1 - w, pw):
            C = c0 + b
            if C < 0 or C + w > cols:
                continue
            base = np.int64(0)  # the window's code with the patch cells cleared
            for i in range(w):
                for j in range(w):
                    if 0 <= a + i < ph and 0 <= b + j < pw:
                        continue
                    if m[(R + i) * cols + C + j]:
                        base |= np.int64(1) << (i * w + j)
            # placements: of the run's first row (lo) and of its other rows (hi), as window bits
            for v in range(n_lo + n_hi):
                lo = v < n_lo
                x = v if lo else v - n_lo
                code = base if lo else np.int64(0)
                for i in range(1 if lo else nr - 1):
                    row = (x >> (i * pw)) & pmask
                    wr = ((row >> b) if b >= 0 else (row << -b)) & wmask
                    code |= wr << ((ra + i + (0 if lo else 1) - a) * w)
                P[v] = code
            for hi in range(n_hi):
                ch = P[n_lo + hi]
                o = hi << pw
                if into:
                    for lo in range(n_lo):
                        out[o + lo] += theta[ch | P[lo]]
                else:
                    for lo in range(n_lo):
                        T[o + lo] += theta[ch | P[lo]]
        if not into:
            sh = ra * pw
            for c in range(n):
                out[c] += T[(c >> sh) & (nk - 1)]


@nb.njit(cache=True)
def _full_range(cands, n, nl):
    if n != np.int64(1) << nl:
        return False
    for j in range(n):
        if cands[j] != j:
            return False
    return True


@nb.njit(cache=True)
def field_patch_weights(lp, patch, m, cands, n, out, ts):
    """``out[j] = log p~(patch = cands[j], rest)`` up to a constant in ``j``: the windows (and, at two
    scales, the pooled windows) holding a live patch cell, read once, then scored per candidate. All
    ``2^L`` candidates in order of a full rectangular patch: by row groups, :func:`_rect_window_sums`;
    of another patch: in Gray-code order, :func:`_window_sums_gray`; a few candidates: each scattered into
    the windows' codes (:func:`_window_sums`). The pooled scale once per configuration of the patch's
    parents, which is all it reads of a candidate."""
    rows, cols, w = lp.rows, lp.cols, lp.w
    theta, theta2 = lp.theta, lp.theta2
    L = patch.shape[0]
    rect = False
    if L <= 20 and n == np.int64(1) << L and _full_range(cands, n, L):
        ph, pw = _rect_shape(patch, cols)
        if _rect_fits(w, ph, pw, ts.memo.shape[0]):
            r0, c0 = patch[0] // cols, patch[0] % cols
            place = np.empty((1 << pw) + (1 << (min(w, ph) * pw - pw)), np.int64)
            if w == 3 and ph == 3 and pw == 3:  # the common case, with its loop bounds known when compiled
                _rect_window_sums(theta, 3, m, rows, cols, r0, c0, 3, 3, out, ts.memo, place)
            else:
                _rect_window_sums(theta, w, m, rows, cols, r0, c0, ph, pw, out, ts.memo, place)
            rect = True
            if lp.n_scales != 2:
                return
    bit_of = ts.bit_of  # K int64, all -1 between updates
    nl = 0
    for i in range(L):
        if patch[i] >= 0:
            nl += 1
    cr = np.empty(max(nl, 1), np.int64)
    cc = np.empty(max(nl, 1), np.int64)
    b = 0
    for i in range(L):
        k = patch[i]
        if k >= 0:
            bit_of[k] = b
            cr[b] = k // cols
            cc[b] = k - cr[b] * cols
            b += 1
    cap = max(nl, 1) * w * w
    if not rect:  # scale 1 by the windows' (patch bit, window bit) pairs
        anchors = np.empty(cap, np.int64)
        base = np.empty(cap, np.int64)
        pr_off = np.empty(cap + 1, np.int64)
        pr_pb = np.empty(cap, np.int64)
        pr_wb = np.empty(cap, np.int64)
        nw = _scale_setup(w, rows, cols, cr, cc, nl, bit_of, m, 0, 0, cols, anchors, base, pr_off, pr_pb, pr_wb)
        if nl <= 20 and _full_range(cands, n, nl):
            _window_sums_gray(theta, nw, base, pr_off, pr_pb, pr_wb, nl, out)
        else:
            _window_sums(theta, nw, base, pr_off, pr_pb, pr_wb, cands, n, out, False)
    for i in range(L):
        if patch[i] >= 0:
            bit_of[patch[i]] = -1
    if lp.n_scales != 2:
        return
    P, Q = lp.prow, lp.pcol
    # the pooled parents of the live cells: per parent the OR of its fixed cells and the mask of its patch bits
    npar = 0
    fixed = np.zeros(max(nl, 1), np.int64)
    pmask = np.zeros(max(nl, 1), np.int64)
    pr_ = np.empty(max(nl, 1), np.int64)
    pc_ = np.empty(max(nl, 1), np.int64)
    for x in range(nl):
        i = cr[x] >> 1
        j = cc[x] >> 1
        q = -1
        for y in range(npar):
            if pr_[y] == i and pc_[y] == j:
                q = y
        if q < 0:
            q = npar
            pr_[q] = i
            pc_[q] = j
            npar += 1
        pmask[q] |= np.int64(1) << x
    # the pooled cells the pooled windows read lie within w - 1 of a parent: a box of them, not the grid
    i0, i1, j0, j1 = P, -1, Q, -1
    for y in range(npar):
        i0, i1 = min(i0, pr_[y] - w + 1), max(i1, pr_[y] + w - 1)
        j0, j1 = min(j0, pc_[y] - w + 1), max(j1, pc_[y] + w - 1)
    i0, j0 = max(i0, 0), max(j0, 0)
    i1, j1 = min(i1, P - 1), min(j1, Q - 1)
    S = j1 - j0 + 1
    is_par = np.full((i1 - i0 + 1) * S, -1, np.int64)
    pooled = np.zeros((i1 - i0 + 1) * S, np.uint8)
    for y in range(npar):
        is_par[(pr_[y] - i0) * S + pc_[y] - j0] = y
        f = 0
        for a in range(2 * pr_[y], min(2 * pr_[y] + 2, rows)):
            for bb in range(2 * pc_[y], min(2 * pc_[y] + 2, cols)):
                kk = a * cols + bb
                live = False
                for x in range(nl):
                    if cr[x] * cols + cc[x] == kk:
                        live = True
                if not live and m[kk]:
                    f = 1
        fixed[y] = f
    for y in range(npar):
        for i in range(max(0, pr_[y] - w + 1), min(P, pr_[y] + w)):
            for j in range(max(0, pc_[y] - w + 1), min(Q, pc_[y] + w)):
                if is_par[(i - i0) * S + j - j0] < 0:
                    pooled[(i - i0) * S + j - j0] = _pooled(m, rows, cols, i, j)
    base2 = np.empty(cap, np.int64)
    p2_off = np.empty(cap + 1, np.int64)
    p2_pb = np.empty(cap, np.int64)
    p2_wb = np.empty(cap, np.int64)
    anchors2 = np.empty(cap, np.int64)
    nw2 = _scale_setup(w, P, Q, pr_, pc_, npar, is_par, pooled, i0, j0, S, anchors2, base2, p2_off, p2_pb, p2_wb)
    pcands = np.empty(max(n, 1), np.int64)  # each candidate's parents' pooled values (bit y: parent y)
    for jx in range(n):
        pbits = np.int64(0)
        for y in range(npar):
            if fixed[y] or (cands[jx] & pmask[y]) != 0:
                pbits |= np.int64(1) << y
        pcands[jx] = pbits
    if npar <= POOLED_TABLE_BITS and (np.int64(1) << npar) < n:
        # the pooled scale depends on a candidate through its parents alone: their 2^npar sums, tabled once
        NP = np.int64(1) << npar
        t2 = np.empty(NP, np.float64)
        _window_sums(theta2, nw2, base2, p2_off, p2_pb, p2_wb, np.arange(NP), NP, t2, False)
        for jx in range(n):
            out[jx] += t2[pcands[jx]]
    else:
        _window_sums(theta2, nw2, base2, p2_off, p2_pb, p2_wb, pcands, n, out, True)


# ------------------------------------------------------------------ whole maps
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


@nb.njit(cache=True)
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
