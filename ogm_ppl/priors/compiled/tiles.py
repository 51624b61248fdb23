r"""Compiled conditionals of the tiles kind (:class:`~ogm_ppl.priors.compiled.bundles.Tiles`).

``log p~(m) = sum_t log phi(key_t(m))`` over the tiles ``t`` of a fixed tiling of the plane by ``h x w``
rectangles; ``key_t`` packs the tile's *window* (the tile and a ring of ``pad`` border cells) into an
integer: bit ``i`` = window cell ``i``, the tile's own cells first (row-major), then the border ring
(row-major in the window). Window cells off the grid read as the tile's ``fill`` bits. ``phi`` is a sparse
table (sorted keys and their log values) per *segment*; a tile names its segment (e.g. the marginal table
of tiles cut by the grid edge). Keys missing from a segment fall back to segment ``fallback`` (keyed by the
tile's own bits only) when its border is unseen, else have ``phi = 0``. The patch tables of Section 5.2.2
(``pad = 0``) and the border-conditioned tables of Section 5.2.3 (``pad = 1``) are both of this kind.

For speed, tables over windows of at most 16 cells are also stored dense (one load per factor); sparse
tables with at most 16 border cells get a border index (:func:`border_index`: the run of keys of each
border in two loads, so a factor is a binary search among the few keys of its border and a tile's
candidates given its border are that run, :func:`border_range`); and a
patch update reads the keys of the tiles it touches once (:func:`tile_patch_setup`), after which a
candidate only ORs in its own bits and each touched tile's factor is memoised per the few bits the patch
sets in it (:func:`tile_patch_factors`). Patch updates whose patch is a tile weigh only the
configurations the tile's table allows given its border (:func:`tile_candidates`, Section 5.2.2 / 5.2.3).
"""

from __future__ import annotations

import numba as nb
import numpy as np

from ogm_ppl.priors.compiled.bundles import Tiles
from ogm_ppl.priors.compiled.registry import register
from ogm_ppl.priors.compiled.scratch import MEMO_BITS

__all__ = [
    "BORDER_INDEX_MAX_BITS",
    "BORDER_INDEX_MAX_ENTRIES",
    "DENSE_MAX_BITS",
    "DENSE_MAX_ENTRIES",
    "border_index",
    "border_range",
    "tile_candidates",
    "tile_escape",
    "tile_cell_log_odds",
    "tile_of_anchor",
    "tile_patch_factors",
    "tile_patch_setup",
    "tiles",
    "tiles_log_prob_batch",
    "touch_capacity",
]

_I = np.zeros(0, np.int64)
_F = np.zeros(0, np.float64)
#: windows of at most this many cells get a dense factor table (at most DENSE_MAX_ENTRIES entries in all)
DENSE_MAX_BITS, DENSE_MAX_ENTRIES = 16, 1 << 20
#: borders of at most this many cells get a border index (at most BORDER_INDEX_MAX_ENTRIES entries in all)
BORDER_INDEX_MAX_BITS, BORDER_INDEX_MAX_ENTRIES = 16, 1 << 22


def border_index(keys: np.ndarray, seg_off: np.ndarray, n_inner: int, B: int) -> np.ndarray:
    """The border index of :func:`border_range`: ``S * (2^B + 1)`` int64, entry ``s (2^B + 1) + b`` the first
    key of segment ``s`` with border code ``>= b`` (``b = 2^B``: the segment's end), by binary search of the
    segment's sorted keys (``key = inner + 2^n_inner b``)."""
    S = len(seg_off) - 1
    bounds = np.arange((1 << B) + 1, dtype=np.int64) << n_inner
    out = np.empty(S * ((1 << B) + 1), np.int64)
    for s in range(S):
        a, b = int(seg_off[s]), int(seg_off[s + 1])
        out[s * ((1 << B) + 1) : (s + 1) * ((1 << B) + 1)] = a + np.searchsorted(keys[a:b], bounds, side="left")
    return out


# Speed: the hot helpers are inlined (``inline="always"``; a call that passes the bundle costs about
# 130 ns in reference counts of its arrays, more than a lookup itself), and each binds the bundle's arrays
# to locals once (numba counts a reference at every ``lp.array`` read: in a loop that costs 5x).
@nb.njit(cache=True, inline="always")
def tile_key(lp, t, m):
    """The window key of tile ``t`` in map ``m``."""
    w_dr, w_dc = lp.w_dr, lp.w_dc
    rows, cols = lp.rows, lp.cols
    ti = t // lp.t_cols
    tj = t - ti * lp.t_cols
    ar = lp.t_r0 + ti * lp.t_h
    ac = lp.t_c0 + tj * lp.t_w
    key = lp.t_fill[t]
    for i in range(w_dr.shape[0]):  # without branches on the map (they mispredict): 4x faster
        r = ar + w_dr[i]
        c = ac + w_dc[i]
        ok = (r >= 0) & (r < rows) & (c >= 0) & (c < cols)
        k = r * cols + c if ok else 0
        key |= np.int64(ok & (m[k] != 0)) << i
    return key


@nb.njit(cache=True, inline="always")
def _lower(keys, lo, hi, key):
    while lo < hi:
        mid = (lo + hi) >> 1
        if keys[mid] < key:
            lo = mid + 1
        else:
            hi = mid
    return lo


@nb.njit(cache=True, inline="always")
def border_range(seg_off, keys, b_start, b_bits, n_inner, s, border):
    """``(lo, hi)``: the keys of segment ``s`` whose border code (``key >> n_inner``) is ``border``, from the
    border index ``b_start`` (two loads) when there is one (``b_bits >= 0``), else by binary search. The keys
    are sorted by ``key = inner + 2^n_inner border``, so each border's keys are one run."""
    if b_bits >= 0:
        q = s * ((np.int64(1) << b_bits) + 1) + border
        return b_start[q], b_start[q + 1]
    a, b = seg_off[s], seg_off[s + 1]
    return _lower(keys, a, b, border << n_inner), _lower(keys, a, b, (border + 1) << n_inner)


def _sparse_factor_py(keys, logp, seg_off, backoff, bseg, n_inner, b_start, b_bits, s, key):
    """``log phi(key)`` in segment ``s`` by binary search of the sorted keys (with a border index, only
    among the keys of the key's border: :func:`border_range`). A key missing from the segment: with a
    border-weight segment ``bseg >= 0`` (a backed-off table) it is ``log lambda_b + log back(inner)``,
    ``lambda_b`` looked up by border in segment ``bseg`` (``1`` for a border never seen) and ``back`` the
    segment ``bseg + 1``, which holds every inner code in order; else it backs off to segment ``backoff``
    (keyed by the inner bits; ``-1``: none) when the key's border was never seen, and is ``-inf``
    otherwise. (Not inlined: a large inlined body slows the loops around it.)"""
    border = key >> n_inner
    if b_bits >= 0:
        q = s * ((np.int64(1) << b_bits) + 1) + border
        lo, hi = b_start[q], b_start[q + 1]
    else:
        lo, hi = seg_off[s], seg_off[s + 1]
    i = _lower(keys, lo, hi, key)
    if i < hi and keys[i] == key:
        return logp[i]
    if bseg >= 0:
        v = logp[seg_off[bseg + 1] + (key & ((np.int64(1) << n_inner) - 1))]
        ba, bb = seg_off[bseg], seg_off[bseg + 1]
        j = _lower(keys, ba, bb, border)
        if j < bb and keys[j] == border:
            v += logp[j]
        return v
    if backoff >= 0:
        if b_bits >= 0:
            seen = lo < hi
        else:
            j = _lower(keys, lo, hi, border << n_inner)
            seen = j < hi and (keys[j] >> n_inner) == border
        if not seen:  # border never seen: back off
            fa, fb = seg_off[backoff], seg_off[backoff + 1]
            inner = key & ((np.int64(1) << n_inner) - 1)
            q = _lower(keys, fa, fb, inner)
            if q < fb and keys[q] == inner:
                return logp[q]
    return -np.inf


_sparse_factor = nb.njit(cache=True)(_sparse_factor_py)
#: the same, inlined: for loops that make few other calls (a call passing the arrays costs more than
#: the search among a border's few keys)
_sparse_factor_inline = nb.njit(cache=True, inline="always")(_sparse_factor_py)


@nb.njit(cache=True, inline="always")
def _factor(dense, dense_bits, keys, logp, seg_off, backoff, bseg, n_inner, b_start, b_bits, s, key):
    """``log phi(key)`` in segment ``s`` from arrays already bound to locals: one load from the dense table
    if ``dense_bits >= 0``, else :func:`_sparse_factor`."""
    if dense_bits >= 0:
        return dense[(s << dense_bits) | key]
    return _sparse_factor(keys, logp, seg_off, backoff, bseg, n_inner, b_start, b_bits, s, key)


@nb.njit(cache=True, inline="always")
def _backoff(lp):
    """The fallback segment when keys have a border to back off from, else ``-1``."""
    return lp.fallback if lp.w_dr.shape[0] > lp.n_inner else -1


@nb.njit(cache=True, inline="always")
def sparse_key_log_factor(lp, s, key):
    """``log phi(key)`` in segment ``s`` from the sorted keys (fallback for an unseen border; ``-inf`` if
    absent)."""
    bo, bseg = _backoff(lp), lp.border_seg
    return _factor(lp.dense, -1, lp.keys, lp.logp, lp.seg_off, bo, bseg, lp.n_inner, lp.b_start, lp.b_bits, s, key)


@nb.njit(cache=True, inline="always")
def key_log_factor(lp, s, key):
    """``log phi(key)`` in segment ``s``: one load from the dense table when there is one, else
    :func:`sparse_key_log_factor`."""
    return _factor(
        lp.dense,
        lp.dense_bits,
        lp.keys,
        lp.logp,
        lp.seg_off,
        _backoff(lp),
        lp.border_seg,
        lp.n_inner,
        lp.b_start,
        lp.b_bits,
        s,
        key,
    )


@nb.njit(cache=True)
def dense_factor_table(lp):
    """``S * 2^Lw`` float64: :func:`sparse_key_log_factor` of every key of every segment."""
    S = lp.seg_off.shape[0] - 1
    Lw = lp.w_dr.shape[0]
    out = np.empty(S << Lw, np.float64)
    for s in range(S):
        for key in range(np.int64(1) << Lw):
            out[(s << Lw) | key] = sparse_key_log_factor(lp, s, key)
    return out


def fallback_dense_table(lp) -> np.ndarray:
    """``2^n_inner`` float64: the fallback segment's ``log phi`` by inner code (``-inf`` where absent), the
    bundle's ``fb_dense``."""
    a, b = int(lp.seg_off[lp.fallback]), int(lp.seg_off[lp.fallback + 1])
    fb = np.full(1 << int(lp.n_inner), -np.inf)
    fk = lp.keys[a:b]
    ok = (fk >= 0) & (fk < (1 << int(lp.n_inner)))
    fb[fk[ok]] = lp.logp[a:b][ok]
    return fb


@nb.njit(cache=True, inline="always")
def tile_log_factor(lp, t, m):
    return key_log_factor(lp, lp.t_seg[t], tile_key(lp, t, m))


@nb.njit(cache=True, inline="always")
def tiles_touching(lp, r, c, out, n):
    """Append to ``out[:n]`` the tiles whose window holds cell ``(r, c)`` (no duplicates); new ``n``."""
    # tile i's window rows are [t_r0 + i h - pad_r, t_r0 + i h + h - 1 + pad_r]
    i0 = max((r - lp.pad_r - lp.t_r0) // lp.t_h - 1, 0)
    i1 = min((r + lp.pad_r - lp.t_r0) // lp.t_h, lp.t_rows - 1)
    j0 = max((c - lp.pad_c - lp.t_c0) // lp.t_w - 1, 0)
    j1 = min((c + lp.pad_c - lp.t_c0) // lp.t_w, lp.t_cols - 1)
    for i in range(i0, i1 + 1):
        ar = lp.t_r0 + i * lp.t_h
        if r < ar - lp.pad_r or r > ar + lp.t_h - 1 + lp.pad_r:
            continue
        for j in range(j0, j1 + 1):
            ac = lp.t_c0 + j * lp.t_w
            if c < ac - lp.pad_c or c > ac + lp.t_w - 1 + lp.pad_c:
                continue
            t = i * lp.t_cols + j
            dup = False
            for q in range(n):
                if out[q] == t:
                    dup = True
                    break
            if not dup:
                out[n] = t
                n += 1
    return n


@nb.njit(cache=True, inline="always")
def _tiles_of_patch(lp, patch, out):
    n = 0
    for i in range(patch.shape[0]):
        k = patch[i]
        if k >= 0:
            r = k // lp.cols
            n = tiles_touching(lp, r, k - r * lp.cols, out, n)
    return n


@nb.njit(cache=True)
def touch_capacity(lp, L):
    """An upper bound on the tiles an ``L``-cell patch touches (and on its (cell, tile) pairs)."""
    per = ((lp.t_h + 2 * lp.pad_r) // lp.t_h + 2) * ((lp.t_w + 2 * lp.pad_c) // lp.t_w + 2)
    return max(L, 1) * per


@nb.njit(cache=True)
def tile_patch_setup(lp, patch, m, skip, ts):
    """Prepare the factors of the tiles whose window holds a cell of ``patch`` (all but tile ``skip``):
    per tile ``q`` its window key with the patch cells read as free (``ts.base[q]``) and the pairs
    (patch bit, window bit) through which a configuration adds bits to that key. The keys do not depend
    on the configuration otherwise, so they are read from the map once per update, not per candidate.
    Returns the number of tiles ``nt``; ``ts.memo_off[nt]`` is the memo size used."""
    w_dr, w_dc, t_fill, t_seg = lp.w_dr, lp.w_dc, lp.t_fill, lp.t_seg
    bit_of, touch, base, seg, pr_off, pr_pb, pr_wb, memo_off, memo = ts
    rows, cols = lp.rows, lp.cols
    nt_all = _tiles_of_patch(lp, patch, touch)
    bit = 0
    for i in range(patch.shape[0]):
        if patch[i] >= 0:
            bit_of[patch[i]] = bit
            bit += 1
    nt = 0
    npair = 0
    mo = 0
    pr_off[0] = 0
    for q in range(nt_all):
        t = touch[q]
        if t == skip:
            continue
        ti = t // lp.t_cols
        ar = lp.t_r0 + ti * lp.t_h
        ac = lp.t_c0 + (t - ti * lp.t_cols) * lp.t_w
        key = t_fill[t]
        for i in range(w_dr.shape[0]):
            r = ar + w_dr[i]
            c = ac + w_dc[i]
            if 0 <= r < rows and 0 <= c < cols:
                k = r * cols + c
                b = bit_of[k]
                if b >= 0:
                    pr_pb[npair] = b
                    pr_wb[npair] = i
                    npair += 1
                elif m[k]:
                    key |= np.int64(1) << i
        touch[nt] = t
        base[nt] = key
        seg[nt] = t_seg[t]
        ns = npair - pr_off[nt]
        pr_off[nt + 1] = npair
        if ns <= MEMO_BITS:
            memo_off[nt] = mo
            for x in range(mo, mo + (1 << ns)):
                memo[x] = np.nan
            mo += 1 << ns
        else:
            memo_off[nt] = -1
        nt += 1
    memo_off[nt] = mo
    for i in range(patch.shape[0]):
        if patch[i] >= 0:
            bit_of[patch[i]] = -1
    return nt


@nb.njit(cache=True)
def tile_patch_factors(lp, nt, ts, cands, n, out):
    """``out[j] += sum_q log phi_q(key_q(cands[j]))`` over the ``nt`` tiles of :func:`tile_patch_setup`
    (entries already ``-inf`` are left alone). A tile's factor depends on a candidate only through the
    bits the candidate sets in its window (for a 3 x 3 tile of a border prior, 3 cells of an edge
    neighbour, 1 of a corner one), so it is memoised per such sub-configuration: a neighbour costs at
    most ``2^shared`` lookups per update, however many candidates there are."""
    _bit_of, _touch, base, seg, pr_off, pr_pb, pr_wb, memo_off, memo = ts
    dense, db, keys, logp, seg_off = lp.dense, lp.dense_bits, lp.keys, lp.logp, lp.seg_off
    backoff, bseg, n_inner, b_start, b_bits = _backoff(lp), lp.border_seg, lp.n_inner, lp.b_start, lp.b_bits
    for j in range(n):
        s = out[j]
        if s == -np.inf:
            continue
        w = cands[j]
        for q in range(nt):
            key = base[q]
            p0 = pr_off[q]
            sub = 0
            for p in range(p0, pr_off[q + 1]):
                if (w >> pr_pb[p]) & 1:
                    key |= np.int64(1) << pr_wb[p]
                    sub |= 1 << (p - p0)
            mo = memo_off[q]
            if mo >= 0:
                v = memo[mo + sub]
                if v != v:
                    v = _factor(dense, db, keys, logp, seg_off, backoff, bseg, n_inner, b_start, b_bits, seg[q], key)
                    memo[mo + sub] = v
            else:
                v = _factor(dense, db, keys, logp, seg_off, backoff, bseg, n_inner, b_start, b_bits, seg[q], key)
            s += v
            if s == -np.inf:
                break
        out[j] = s


@nb.njit(cache=True, inline="always")
def _tile_cell_terms(lp, k, m, dense_path):
    """``(s1, s0)``: the summed log factors of the tiles whose window holds ``k`` with ``m_k = 1`` and with
    ``m_k = 0``. Each tile's key is read once with ``k`` free; ``k``'s bit is then set for the occupied
    value. ``dense_path``: look the keys up in the dense table (else by binary search)."""
    w_dr, w_dc, t_fill, t_seg, dense = lp.w_dr, lp.w_dc, lp.t_fill, lp.t_seg, lp.dense
    db = lp.dense_bits
    rows, cols = lp.rows, lp.cols
    t_h, t_w, pad_r, pad_c, t_r0, t_c0, t_cols = lp.t_h, lp.t_w, lp.pad_r, lp.pad_c, lp.t_r0, lp.t_c0, lp.t_cols
    Lw = w_dr.shape[0]
    r = k // cols
    c = k - r * cols
    i0 = max((r - pad_r - t_r0) // t_h - 1, 0)
    i1 = min((r + pad_r - t_r0) // t_h, lp.t_rows - 1)
    j0 = max((c - pad_c - t_c0) // t_w - 1, 0)
    j1 = min((c + pad_c - t_c0) // t_w, t_cols - 1)
    s1 = 0.0
    s0 = 0.0
    for i in range(i0, i1 + 1):
        ar = t_r0 + i * t_h
        if r < ar - pad_r or r > ar + t_h - 1 + pad_r:
            continue
        for j in range(j0, j1 + 1):
            ac = t_c0 + j * t_w
            if c < ac - pad_c or c > ac + t_w - 1 + pad_c:
                continue
            t = i * t_cols + j
            key = t_fill[t]
            kbit = np.int64(0)
            for q in range(Lw):
                rr = ar + w_dr[q]
                cc = ac + w_dc[q]
                if 0 <= rr < rows and 0 <= cc < cols:
                    kk = rr * cols + cc
                    if kk == k:
                        kbit = np.int64(1) << q
                    elif m[kk]:
                        key |= np.int64(1) << q
            s = t_seg[t]
            if dense_path:
                s1 += dense[(s << db) | key | kbit]
                s0 += dense[(s << db) | key]
            else:
                s1 += sparse_key_log_factor(lp, s, key | kbit)
                s0 += sparse_key_log_factor(lp, s, key)
    return s1, s0


@nb.njit(cache=True)
def _tile_cell_log_odds_sparse(lp, k, m):
    s1, s0 = _tile_cell_terms(lp, k, m, False)
    return s1 - s0


@nb.njit(cache=True, inline="always")
def tile_cell_log_odds(lp, k, m):
    """:func:`cell_log_odds` of a tiles prior: the factors of the tiles whose window holds ``k``."""
    if lp.dense_bits < 0:
        return _tile_cell_log_odds_sparse(lp, k, m)
    s1, s0 = _tile_cell_terms(lp, k, m, True)
    return s1 - s0


@nb.njit(cache=True, inline="always")
def tile_of_anchor(lp, r0, c0, h, w):
    """The tile whose cells are exactly the ``h x w`` rectangle at ``(r0, c0)``, or ``-1``."""
    if h != lp.t_h or w != lp.t_w:
        return -1
    dr = r0 - lp.t_r0
    dc = c0 - lp.t_c0
    if dr % lp.t_h != 0 or dc % lp.t_w != 0:
        return -1
    i = dr // lp.t_h
    j = dc // lp.t_w
    if i < 0 or j < 0 or i >= lp.t_rows or j >= lp.t_cols:
        return -1
    return i * lp.t_cols + j


@nb.njit(cache=True, inline="always")
def tile_candidates(lp, t, patch, pinned, m, cands, cand_lp):
    """Configurations of tile ``t`` (whose cells, row-major, are ``patch``; ``-1`` off the grid or
    pinned) that its own factor allows given the current border: the sparse support of Section 5.2.2 /
    5.2.3. Written to ``cands`` as live-bit codes, with tile ``t``'s own ``log phi`` of each in
    ``cand_lp``; returns how many (``-1`` if ``cands`` is too small)."""
    keys, logp, seg_off, w_dr, w_dc = lp.keys, lp.logp, lp.seg_off, lp.w_dr, lp.w_dc
    key = tile_key(lp, t, m)
    Li = lp.n_inner
    border = key >> Li
    s = lp.t_seg[t]
    lo, hi = border_range(seg_off, keys, lp.b_start, lp.b_bits, Li, s, border)
    if lo == hi and _backoff(lp) >= 0:
        lo, hi = seg_off[lp.fallback], seg_off[lp.fallback + 1]
    fill = lp.t_fill[t]
    ti = t // lp.t_cols
    ar = lp.t_r0 + ti * lp.t_h
    ac = lp.t_c0 + (t - ti * lp.t_cols) * lp.t_w
    live = 0
    for i in range(Li):
        if patch[i] >= 0:
            live += 1
    if live == Li:  # every tile cell is live: the codes are the inner keys themselves (a loop LLVM vectorises)
        if hi - lo > cands.shape[0]:
            return -1
        inner_mask = (np.int64(1) << Li) - 1
        for q in range(lo, hi):
            cands[q - lo] = keys[q] & inner_mask
            cand_lp[q - lo] = logp[q]
        return hi - lo
    n = 0
    for q in range(lo, hi):
        inner = keys[q] & ((np.int64(1) << Li) - 1)
        ok = True
        code = 0
        bit = 0
        for i in range(Li):
            v = (inner >> i) & 1
            if patch[i] >= 0:
                if v:
                    code |= np.int64(1) << bit
                bit += 1
            else:
                r = ar + w_dr[i]
                c = ac + w_dc[i]
                if 0 <= r < lp.rows and 0 <= c < lp.cols:
                    if v:  # a pinned cell is free
                        ok = False
                        break
                elif v != ((fill >> i) & 1):
                    ok = False
                    break
        if ok:
            if n >= cands.shape[0]:
                return -1
            cands[n] = code
            cand_lp[n] = logp[q]
            n += 1
    return n


@nb.njit(cache=True)
def tiles_log_prob_batch(lp, maps, out):
    """``sum_t log phi_t(m)`` for every row of ``maps`` (``B x K`` uint8)."""
    T = lp.t_rows * lp.t_cols
    for b in range(maps.shape[0]):
        s = 0.0
        for t in range(T):
            s += tile_log_factor(lp, t, maps[b])
        out[b] = s


#: a neighbour layout is built for tiles of at most this many cells (its index is ``2^n_inner x nq``)
LAYOUT_MAX_INNER = 12


def neighbour_layout(w_dr, w_dc, n_inner, tile, pad, cols, memo_bits=MEMO_BITS) -> dict:
    """The neighbour layout of a tile update away from the grid edge (the ``nb_*`` fields of
    :class:`Tiles`): the tiles other than ``t`` whose windows hold a cell of ``t``, listed in the order of
    :func:`tile_patch_setup` (by :func:`tiles_touching` of each tile cell in turn), each with the
    (tile bit, window bit) pairs through which the tile's configuration enters that neighbour's key.
    For a tile whose every cell is live and whose neighbours' windows lie on the grid, these depend on
    the tiling alone, so :func:`tile_candidate_weights` reads them instead of building them per update.
    Empty (no layout) for windows without a border, tiles of more than :data:`LAYOUT_MAX_INNER` cells or
    a neighbour sharing more than ``memo_bits`` cells."""
    h, w = int(tile[0]), int(tile[1])
    pr, pc = int(pad[0]), int(pad[1])
    empty = {k: np.zeros(0, np.int64) for k in ("nb_lin", "nb_dt", "nb_pmask", "nb_eoff", "nb_expand", "nb_idx")}
    empty["nb_box"] = np.zeros(0, np.int64)
    if (pr == 0 and pc == 0) or n_inner > LAYOUT_MAX_INNER:
        return empty
    w_dr = np.asarray(w_dr, np.int64)
    w_dc = np.asarray(w_dc, np.int64)
    # a virtual tiling with tile (t_i, t_j) far from any edge, anchored at (t_i h, t_j w)
    t_i, t_j = pr // h + 2, pc // w + 2
    ar, ac = t_i * h, t_j * w
    touched: list[tuple[int, int]] = []
    for i in range(n_inner):
        r, c = ar + int(w_dr[i]), ac + int(w_dc[i])
        for ti in range(max((r - pr) // h - 1, 0), (r + pr) // h + 1):
            a = ti * h
            if r < a - pr or r > a + h - 1 + pr:
                continue
            for tj in range(max((c - pc) // w - 1, 0), (c + pc) // w + 1):
                b = tj * w
                if c < b - pc or c > b + w - 1 + pc:
                    continue
                if (ti, tj) not in touched:
                    touched.append((ti, tj))
    nb = [(ti - t_i, tj - t_j) for ti, tj in touched if (ti, tj) != (t_i, t_j)]
    lin, dt, pmask, eoff, expand = [], [], [], [0], []
    sub_pairs = []
    rmin = cmin = 1 << 30
    rmax = cmax = -(1 << 30)
    for di, dj in nb:
        pairs = []  # (tile bit, window bit) in window-bit order
        for x in range(len(w_dr)):
            rr, cc = di * h + int(w_dr[x]), dj * w + int(w_dc[x])
            rmin, rmax, cmin, cmax = min(rmin, rr), max(rmax, rr), min(cmin, cc), max(cmax, cc)
            if 0 <= rr < h and 0 <= cc < w:
                pairs.append((rr * w + cc, x))
        if len(pairs) > memo_bits:
            return empty
        lin.append(di * h * int(cols) + dj * w)
        dt.append((di, dj))
        pmask.append(sum(1 << x for _, x in pairs))
        for sub in range(1 << len(pairs)):
            expand.append(sum(1 << x for p, (_, x) in enumerate(pairs) if (sub >> p) & 1))
        eoff.append(len(expand))
        sub_pairs.append(pairs)
    nq = len(nb)
    idx = np.empty((1 << n_inner, nq), np.int64)
    codes = np.arange(1 << n_inner, dtype=np.int64)
    for q, pairs in enumerate(sub_pairs):
        sub_code = np.zeros(1 << n_inner, np.int64)
        for p, (b, _) in enumerate(pairs):
            sub_code |= ((codes >> b) & 1) << p
        idx[:, q] = eoff[q] + sub_code
    return {
        "nb_lin": np.asarray(lin, np.int64),
        "nb_dt": np.asarray(dt, np.int64).reshape(-1),  # (di, dj) of each neighbour, flat
        "nb_pmask": np.asarray(pmask, np.int64),
        "nb_eoff": np.asarray(eoff, np.int64),
        "nb_expand": np.asarray(expand, np.int64),
        "nb_idx": np.ascontiguousarray(idx.ravel()),
        "nb_box": np.asarray([rmin, rmax, cmin, cmax], np.int64),
    }


def tiles(
    rows,
    cols,
    geometry,
    n_inner,
    tile,
    pad,
    t_seg,
    t_fill,
    seg_keys,
    seg_logp,
    fallback=-1,
    border_seg=-1,
    back_cdf=None,
) -> Tiles:
    """A :class:`Tiles` bundle from a tiling (``geometry``: :func:`~ogm_ppl.priors.local.tiling`) and
    per-segment (keys, log-values) lists; windows of at most :data:`DENSE_MAX_BITS` cells also get the
    dense table. A backed-off table (:class:`~ogm_ppl.priors.backoff.BackoffBorderPrior`) names its
    border-weight segment ``border_seg`` (keys: border codes, values ``log lambda_b``), followed by the
    segment of ``log back`` over every inner code in order, and passes the back-off table's cumulative
    sums ``back_cdf`` (``2^n_inner``, last entry 1); its ``fallback`` segment is then only the candidate
    set of a tile whose border was never seen."""
    if border_seg >= 0:
        fk = np.asarray(seg_keys[border_seg + 1])
        if not np.array_equal(fk, np.arange(1 << int(n_inner))):
            raise ValueError("a backed-off table's back-off segment must hold every inner code in order")
        cdf = np.asarray(back_cdf, np.float64)
        if cdf.shape != (1 << int(n_inner),) or (np.diff(cdf) < 0).any() or cdf[-1] != 1.0:
            raise ValueError("back_cdf must be the non-decreasing cumulative sums of 2^n_inner entries, ending at 1")
    w_dr, w_dc, r0, c0, t_rows, t_cols, _ = geometry
    seg_off = np.zeros(len(seg_keys) + 1, np.int64)
    keys, logp = [], []
    for s, (k, lp) in enumerate(zip(seg_keys, seg_logp)):
        order = np.argsort(k, kind="stable")
        keys.append(np.asarray(k, np.int64)[order])
        logp.append(np.asarray(lp, np.float64)[order])
        seg_off[s + 1] = seg_off[s] + len(k)
    bundle = Tiles(
        rows=int(rows),
        cols=int(cols),
        w_dr=w_dr,
        w_dc=w_dc,
        n_inner=int(n_inner),
        t_h=int(tile[0]),
        t_w=int(tile[1]),
        t_r0=int(r0),
        t_c0=int(c0),
        t_rows=int(t_rows),
        t_cols=int(t_cols),
        pad_r=int(pad[0]),
        pad_c=int(pad[1]),
        t_seg=np.ascontiguousarray(t_seg, np.int64),
        t_fill=np.ascontiguousarray(t_fill, np.int64),
        seg_off=seg_off,
        keys=np.ascontiguousarray(np.concatenate(keys) if keys else _I, np.int64),
        logp=np.ascontiguousarray(np.concatenate(logp) if logp else _F, np.float64),
        fallback=int(fallback),
        dense=_F,
        dense_bits=-1,
        border_seg=int(border_seg),
        back_cdf=np.ascontiguousarray(back_cdf if border_seg >= 0 else _F, np.float64),
    )
    bundle = bundle._replace(
        w_lin=np.ascontiguousarray(np.asarray(w_dr, np.int64) * int(cols) + np.asarray(w_dc, np.int64)),
        **neighbour_layout(w_dr, w_dc, int(n_inner), tile, pad, int(cols)),
    )
    if bundle.fallback >= 0 and int(n_inner) <= DENSE_MAX_BITS:
        bundle = bundle._replace(fb_dense=fallback_dense_table(bundle))
    Lw = len(w_dr)
    B = Lw - int(n_inner)
    if B <= BORDER_INDEX_MAX_BITS and (len(seg_keys) << B) <= BORDER_INDEX_MAX_ENTRIES:
        bundle = bundle._replace(b_start=border_index(bundle.keys, seg_off, int(n_inner), B), b_bits=B)
    if Lw <= DENSE_MAX_BITS and (len(seg_keys) << Lw) <= DENSE_MAX_ENTRIES:
        bundle = bundle._replace(dense=dense_factor_table(bundle), dense_bits=Lw)
    return bundle


@nb.njit(cache=True)
def tiles_patch_weights(lp, patch, m, cands, n, out, ts):
    """``out[j] = log p(patch = cands[j], rest)`` up to a constant in ``j``: the factors of the tiles whose
    window holds a patch cell, through the scratch ``ts``."""
    for j in range(n):
        out[j] = 0.0
    nt = tile_patch_setup(lp, patch, m, -1, ts)
    tile_patch_factors(lp, nt, ts, cands, n, out)


@nb.njit(cache=True, inline="always")
def _layout_applies(lp, t, patch):
    """Whether the update of tile ``t`` (cells ``patch``) can read the neighbour layout: there is one,
    every tile cell is live, and every neighbour's window lies on the grid."""
    if lp.nb_lin.shape[0] == 0:
        return False
    for i in range(lp.n_inner):
        if patch[i] < 0:
            return False
    ti = t // lp.t_cols
    ar = lp.t_r0 + ti * lp.t_h
    ac = lp.t_c0 + (t - ti * lp.t_cols) * lp.t_w
    box = lp.nb_box
    return ar + box[0] >= 0 and ar + box[1] < lp.rows and ac + box[2] >= 0 and ac + box[3] < lp.cols


@nb.njit(cache=True, inline="always")
def tile_neighbour_factors(lp, t, m, cands, n, out, E):
    """:func:`tile_patch_setup` + :func:`tile_patch_factors` for a tile ``t`` where :func:`_layout_applies`:
    ``out[j] += sum_q log phi_q(key_q(cands[j]))`` over the neighbours ``q`` of the layout, in the same
    order and with the same factors (so the same sums, bit for bit). Each neighbour's key with the tile's
    cells free is read from the map through the window's linear offsets, and its factor under every
    sub-configuration of the cells it shares with the tile goes into ``E`` (``nb_eoff[nq]`` entries: for a
    3 x 3 border table, 8 per edge neighbour and 2 per corner one); a candidate then adds one entry of
    ``E`` per neighbour (``nb_idx``), a loop without branches."""
    nb_lin, nb_dt, nb_pmask = lp.nb_lin, lp.nb_dt, lp.nb_pmask
    nb_eoff, nb_expand, nb_idx = lp.nb_eoff, lp.nb_expand, lp.nb_idx
    w_lin, t_fill, t_seg = lp.w_lin, lp.t_fill, lp.t_seg
    dense, db, keys, logp, seg_off = lp.dense, lp.dense_bits, lp.keys, lp.logp, lp.seg_off
    backoff, bseg, n_inner, b_start, b_bits = _backoff(lp), lp.border_seg, lp.n_inner, lp.b_start, lp.b_bits
    fb_dense = lp.fb_dense
    fast = b_bits >= 0 and bseg < 0 and (backoff < 0 or fb_dense.shape[0] > 0)
    b_len = (np.int64(1) << b_bits) + 1 if b_bits >= 0 else np.int64(0)
    inner_mask = (np.int64(1) << n_inner) - 1
    t_cols = lp.t_cols
    nq = nb_lin.shape[0]
    Lw = w_lin.shape[0]
    ti = t // t_cols
    anchor = (lp.t_r0 + ti * lp.t_h) * lp.cols + lp.t_c0 + (t - ti * t_cols) * lp.t_w
    for q in range(nq):
        tq = t + nb_dt[2 * q] * t_cols + nb_dt[2 * q + 1]
        a = anchor + nb_lin[q]
        key = np.int64(0)
        for x in range(Lw):
            if m[a + w_lin[x]]:
                key |= np.int64(1) << x
        base = t_fill[tq] | (key & ~nb_pmask[q])
        s = t_seg[tq]
        for e in range(nb_eoff[q], nb_eoff[q + 1]):
            key = base | nb_expand[e]
            if db >= 0:
                E[e] = dense[(s << db) | key]
            elif fast:  # _sparse_factor with the border index and the dense fallback
                bq = s * b_len + (key >> n_inner)
                lo, hi = b_start[bq], b_start[bq + 1]
                i = _lower(keys, lo, hi, key)
                if i < hi and keys[i] == key:
                    E[e] = logp[i]
                elif lo == hi and backoff >= 0:  # border never seen: back off
                    E[e] = fb_dense[key & inner_mask]
                else:
                    E[e] = -np.inf
            else:
                E[e] = _sparse_factor_inline(keys, logp, seg_off, backoff, bseg, n_inner, b_start, b_bits, s, key)
    if nq == 8:  # a 3 x 3 tile under a one-cell border: the same sums, in the same order, unrolled
        for j in range(n):
            r = cands[j] * 8
            out[j] = (
                out[j]
                + E[nb_idx[r]]
                + E[nb_idx[r + 1]]
                + E[nb_idx[r + 2]]
                + E[nb_idx[r + 3]]
                + E[nb_idx[r + 4]]
                + E[nb_idx[r + 5]]
                + E[nb_idx[r + 6]]
                + E[nb_idx[r + 7]]
            )
        return
    for j in range(n):
        v = out[j]
        row = cands[j] * nq
        for q in range(nq):
            v += E[nb_idx[row + q]]  # -inf stays -inf (no factor is +inf), as the generic update's early exit
        out[j] = v


@nb.njit(cache=True)
def tile_candidate_weights(lp, patch, m, cands, n, t, cand_lp, out, ts):
    """The weights of the candidates of a patch: for a tile ``t >= 0``, its own factor (read with the
    candidates, ``cand_lp``) plus those of its neighbours whose windows hold patch cells (none when the
    windows have no border, ``pad = 0``: the patch tables of Section 5.2.2; through the neighbour layout,
    :func:`tile_neighbour_factors`, where it applies); else :func:`tiles_patch_weights`."""
    if t < 0:
        tiles_patch_weights(lp, patch, m, cands, n, out, ts)
        return
    for j in range(n):
        out[j] = cand_lp[j]
    if lp.pad_r == 0 and lp.pad_c == 0:
        return  # windows without a border: no other tile's window holds a cell of tile t
    if _layout_applies(lp, t, patch):
        tile_neighbour_factors(lp, t, m, cands, n, out, ts.memo)
        return
    nt = tile_patch_setup(lp, patch, m, t, ts)
    tile_patch_factors(lp, nt, ts, cands, n, out)


@nb.njit(cache=True)
def tile_escape(lp, t, patch, m, u, pair_lp):
    """The escape proposal of a backed-off table for tile ``t`` (cells ``patch``, row-major, ``-1`` off
    the grid or pinned): an inner code ``i' ~ back`` drawn by inverse CDF with the uniform ``u``
    (``P(i') = back_cdf[i'] - back_cdf[i' - 1]``, exactly the chance the draw lands on ``i'``).

    Returns ``(prop, log q(cur) - log q(prop))`` with ``prop`` the proposal as a live-bit code, and
    writes tile ``t``'s own ``log phi`` of the current and the proposed configuration to
    ``pair_lp[0], pair_lp[1]``. ``prop = -1`` (a rejected proposal, the state stays) when ``i'`` sets a
    pinned cell or disagrees with the fill of a cell off the grid: the proposal kernel restricted to the
    compatible codes, the rest of its mass left at the current state, is still an independence
    proposal, so the Metropolis-Hastings ratio keeps ``q = back``."""
    cdf = lp.back_cdf
    Li = lp.n_inner
    W = cdf.shape[0]
    lo, hi = 0, W - 1
    while lo < hi:  # the first code with cdf > u
        mid = (lo + hi) >> 1
        if cdf[mid] > u:
            hi = mid
        else:
            lo = mid + 1
    prop_inner = np.int64(lo)
    key = tile_key(lp, t, m)
    mask = (np.int64(1) << Li) - 1
    cur_inner = key & mask
    code = np.int64(0)
    bit = 0
    for i in range(Li):
        v = (prop_inner >> i) & 1
        if patch[i] >= 0:
            if v:
                code |= np.int64(1) << bit
            bit += 1
        elif v != ((cur_inner >> i) & 1):  # a cell the update cannot change (off the grid, pinned)
            return np.int64(-1), 0.0
    q_cur = cdf[cur_inner] - (cdf[cur_inner - 1] if cur_inner > 0 else 0.0)
    q_prop = cdf[prop_inner] - (cdf[prop_inner - 1] if prop_inner > 0 else 0.0)
    if q_cur <= 0.0 or q_prop <= 0.0:
        return np.int64(-1), 0.0
    s = lp.t_seg[t]
    pair_lp[0] = key_log_factor(lp, s, key)
    pair_lp[1] = key_log_factor(lp, s, (key & ~mask) | prop_inner)
    return code, np.log(q_cur) - np.log(q_prop)


def _cell(prior, k, m):
    return tile_cell_log_odds(prior, k, m)


def _patch(prior, patch, m, cands, n, out, ts):
    tiles_patch_weights(prior, patch, m, cands, n, out, ts)


def _cands(prior, r0, c0, h, w, patch, n_live, pinned, m, cands, cand_lp):
    t = tile_of_anchor(prior, r0, c0, h, w)
    if t >= 0:
        return np.int64(tile_candidates(prior, t, patch, pinned, m, cands, cand_lp)), t
    if n_live > 62 or (np.int64(1) << n_live) > cands.shape[0]:
        return np.int64(-1), t
    W = np.int64(1) << n_live
    for j in range(W):
        cands[j] = j
    return W, t


def _weights(prior, patch, m, cands, n, tag, cand_lp, out, ts):
    tile_candidate_weights(prior, patch, m, cands, n, tag, cand_lp, out, ts)


def _capacity(prior, L):
    return touch_capacity(prior, L)


def _restricted(prior, tag):
    return tag >= 0 and prior.border_seg >= 0


def _escape(prior, tag, patch, m, u, pair_lp):
    return tile_escape(prior, tag, patch, m, u, pair_lp)


def _shared(prior):
    # windows without a border (pad = 0): a full tile's candidates and weights are its segment's
    return prior.seg_off.shape[0] - 1 if prior.pad_r == 0 and prior.pad_c == 0 else 0


def _shared_key(prior, r0, c0, h, w, n_live):
    if n_live != prior.n_inner or prior.pad_r != 0 or prior.pad_c != 0 or prior.border_seg >= 0:
        return np.int64(-1)
    t = tile_of_anchor(prior, r0, c0, h, w)
    return np.int64(-1) if t < 0 else np.int64(prior.t_seg[t])


register(
    Tiles,
    cell_log_odds=_cell,
    patch_prior_weights=_patch,
    patch_candidates=_cands,
    candidate_weights=_weights,
    scratch_capacity=_capacity,
    restricted=_restricted,
    escape_proposal=_escape,
    shared_weights=_shared,
    shared_weights_key=_shared_key,
    patch_allocates=False,
)
