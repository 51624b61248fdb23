"""The patch conditionals of the pattern-field kind (:class:`~ogm_ppl.priors.compiled.field.PatternField`): a
patch's configurations weighed by the window sums they change, at each scale (:func:`field_patch_weights`), with
a Gray-code walk over the candidates for large patches and a rectangle fast path."""

from __future__ import annotations

from typing import NamedTuple

import numba as nb
import numpy as np

from ogm_ppl._numba_cache import njit_shipped

__all__ = ["field_patch_weights"]


class CellBox(NamedTuple):
    """Per-cell arrays over a box of a grid (one numba argument): cell ``(i, j)`` at ``(i - o_r) S + j - o_c``
    (the whole grid: ``o_r = o_c = 0``, ``S`` its columns)."""

    is_live: np.ndarray  # int64: the cell's live index, or -1
    value: np.ndarray  # 0/1: the cell's value (read where not live)
    o_r: int  # the box's first row
    o_c: int  # its first column
    S: int  # its row stride


class WindowPairs(NamedTuple):
    """The windows holding a live cell, as :func:`_scale_setup` fills them (one numba argument; room for
    ``n_live w^2`` windows): per window its anchor, its code with the live cells cleared, and its (live index,
    window bit) pairs (CSR ``pr_off`` over ``pr_pb`` / ``pr_wb``)."""

    anchors: np.ndarray  # int64: the window's top-left cell r0 C + c0
    base: np.ndarray  # int64: its code with the live cells cleared
    pr_off: np.ndarray  # int64, one more: where the window's pairs start
    pr_pb: np.ndarray  # int64: the pair's live index (the candidate's bit)
    pr_wb: np.ndarray  # int64: the pair's window bit


@nb.njit(cache=True, inline="always")
def _window_pairs(cap):
    """A :class:`WindowPairs` with room for ``cap`` windows (and pairs)."""
    return WindowPairs(
        np.empty(cap, np.int64),
        np.empty(cap, np.int64),
        np.empty(cap + 1, np.int64),
        np.empty(cap, np.int64),
        np.empty(cap, np.int64),
    )


class PatchRect(NamedTuple):
    """A full ``ph x pw`` rectangular patch with top-left cell ``(r0, c0)``."""

    r0: int
    c0: int
    ph: int
    pw: int


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


@nb.njit(cache=True)
def _scale_setup(w, R, C, cells_r, cells_c, n_live, box, win):
    """The ``w x w`` windows of an ``R x C`` grid holding one of the ``n_live`` live cells
    ``(cells_r, cells_c)``, into ``win`` (:class:`WindowPairs`): per window its anchor, its code with the
    live cells cleared (other cells read from ``box.value``) and the pairs (live index, window bit). ``box``
    (:class:`CellBox`): the whole grid, or a box around the live cells that holds every window's cells.
    Returns the number of windows."""
    is_live, value, o_r, o_c, S = box
    anchors, base, pr_off, pr_pb, pr_wb = win
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
def _window_sums(theta, nw, win, cands, n, out, add):
    """``out[j] = sum_q theta[code_q(cands[j])]`` over the ``nw`` windows ``win`` of :func:`_scale_setup`,
    each candidate's bits placed into every window code (``add``: added to ``out[j]``, term by term)."""
    _, base, pr_off, pr_pb, pr_wb = win
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
def _window_sums_gray(theta, nw, win, nl, out):
    """:func:`_window_sums` for the ``2^nl`` candidates ``0 .. 2^nl - 1`` in order, visited in Gray-code
    order: step ``i`` flips live bit ``ctz(i)``, which changes only the windows holding that cell (9 of the 25
    of a 3 x 3 patch under 3 x 3 windows), so the sum moves by their ``theta`` differences; it is summed afresh
    every :data:`GRAY_RESYNC` steps. Equal to :func:`_window_sums` to rounding (a few ulp of the sums)."""
    _, base, pr_off, pr_pb, pr_wb = win
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
def _rect_window_sums(theta, w, m, rows, cols, rect, out, T, P):
    r"""``out[c] = sum_q theta[code_q(c)]`` for every configuration ``c < 2^(ph pw)`` of the full
    ``ph x pw`` patch at ``(r0, c0)`` (``rect``: a :class:`PatchRect`) of the ``rows x cols`` map ``m`` (bit
    ``a pw + b``: patch cell ``(a, b)``), over the ``w x w`` windows
    inside the grid that hold a patch cell. A window whose top row is ``a`` rows below the patch's holds the
    patch rows ``max(a, 0) .. min(a + w - 1, ph - 1)``, a contiguous run of ``k`` bits of ``c``: the windows
    of one ``a`` (a row group) are summed into one table ``T`` over the run's ``2^k`` configurations ``s``,
    and ``c`` adds one entry of each group's table. A window's code of ``s`` is its code with the patch
    cleared, OR the placement of the run's first patch row (``2^pw`` entries) and of its other rows
    (``2^(k - pw)``), two small tables built per window (in ``P``). A ``3 x 3`` patch under ``3 x 3`` windows:
    five groups of five windows, tables of 8, 64, 512, 64 and 8 entries, then five reads per configuration.
    ``T``: room for ``2^k`` of the largest group (float64); ``P``: for ``2^pw + 2^(k - pw)`` codes (int64)."""
    r0, c0, ph, pw = rect
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
def live_cells(patch, bit_of, cols):
    """The live (``>= 0``) cells of ``patch`` numbered by bit: ``bit_of[k] = b`` for the ``b``-th live cell ``k``
    (the caller resets it to -1 after the update), and their rows and columns on a grid of ``cols`` columns.
    Returns ``(nl, rows, cols)`` (arrays of ``max(nl, 1)``)."""
    L = patch.shape[0]
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
    return nl, cr, cc


@nb.njit(cache=True)
def full_range(cands, n, nl):
    """Whether the ``n`` candidates are ``0 .. 2^nl - 1`` in order (every configuration of ``nl <= 20`` live
    cells: the Gray-code walk applies)."""
    if nl > 20 or n != np.int64(1) << nl:
        return False
    for j in range(n):
        if cands[j] != j:
            return False
    return True


@njit_shipped
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
    if L <= 20 and n == np.int64(1) << L and full_range(cands, n, L):
        ph, pw = _rect_shape(patch, cols)
        if _rect_fits(w, ph, pw, ts.memo.shape[0]):
            r0, c0 = patch[0] // cols, patch[0] % cols
            place = np.empty((1 << pw) + (1 << (min(w, ph) * pw - pw)), np.int64)
            if w == 3 and ph == 3 and pw == 3:  # the common case, with its loop bounds known when compiled
                _rect_window_sums(theta, 3, m, rows, cols, PatchRect(r0, c0, 3, 3), out, ts.memo, place)
            else:
                _rect_window_sums(theta, w, m, rows, cols, PatchRect(r0, c0, ph, pw), out, ts.memo, place)
            rect = True
            if lp.n_scales != 2:
                return
    bit_of = ts.bit_of  # K int64, all -1 between updates
    nl, cr, cc = live_cells(patch, bit_of, cols)
    cap = max(nl, 1) * w * w
    if not rect:  # scale 1 by the windows' (patch bit, window bit) pairs
        win = _window_pairs(cap)
        nw = _scale_setup(w, rows, cols, cr, cc, np.int64(nl), CellBox(bit_of, m, 0, 0, cols), win)
        if nl <= 20 and full_range(cands, n, nl):
            _window_sums_gray(theta, nw, win, nl, out)
        else:
            _window_sums(theta, nw, win, cands, n, out, np.bool_(False))
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
    win2 = _window_pairs(cap)
    nw2 = _scale_setup(w, P, Q, pr_, pc_, np.int64(npar), CellBox(is_par, pooled, i0, j0, S), win2)
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
        _window_sums(theta2, nw2, win2, np.arange(NP), NP, t2, np.bool_(False))
        for jx in range(n):
            out[jx] += t2[pcands[jx]]
    else:
        _window_sums(theta2, nw2, win2, pcands, n, out, np.bool_(True))


# ------------------------------------------------------------------ whole maps
