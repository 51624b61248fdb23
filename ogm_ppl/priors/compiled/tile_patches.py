"""The cell and patch conditionals of the tiles kind (:class:`~ogm_ppl.priors.compiled.tiles.Tiles`): the tiles a
cell or a patch touches, a patch's touched-tile keys read once and their factors memoised per the bits the patch
sets (:func:`tile_patch_setup`, :func:`tile_patch_factors`), a tile's candidates given its border
(:func:`tile_candidates`, Sections 5.2.2 / 5.2.3), the neighbour factors of a patch and the back-off escape move."""

from __future__ import annotations

import numpy as np

from ogm_ppl._numba_cache import njit_shipped
from ogm_ppl.priors.compiled.scratch import MEMO_BITS
from ogm_ppl.priors.compiled.tile_factors import (
    _backoff,
    _factor,
    _lower,
    _sparse_factor_inline,
    border_range,
    key_log_factor,
    sparse_key_log_factor,
    sparse_table,
    tile_key,
)

__all__ = [
    "tile_candidate_weights",
    "tile_candidates",
    "tile_cell_log_odds",
    "tile_escape",
    "tile_of_anchor",
    "tile_patch_factors",
    "tile_patch_setup",
    "tiles_log_prob_batch",
    "tiles_patch_weights",
    "touch_capacity",
]


@njit_shipped(inline="always")
def tile_log_factor(lp, t, m):
    return key_log_factor(lp, lp.t_seg[t], tile_key(lp, t, m))


@njit_shipped(inline="always")
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


@njit_shipped(inline="always")
def _tiles_of_patch(lp, patch, out):
    n = 0
    for i in range(patch.shape[0]):
        k = patch[i]
        if k >= 0:
            r = k // lp.cols
            n = tiles_touching(lp, r, k - r * lp.cols, out, n)
    return n


@njit_shipped
def touch_capacity(lp, L):
    """An upper bound on the tiles an ``L``-cell patch touches (and on its (cell, tile) pairs)."""
    per = ((lp.t_h + 2 * lp.pad_r) // lp.t_h + 2) * ((lp.t_w + 2 * lp.pad_c) // lp.t_w + 2)
    return max(L, 1) * per


@njit_shipped
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


@njit_shipped
def tile_patch_factors(lp, nt, ts, cands, n, out):
    """``out[j] += sum_q log phi_q(key_q(cands[j]))`` over the ``nt`` tiles of :func:`tile_patch_setup`
    (entries already ``-inf`` are left alone). A tile's factor depends on a candidate only through the
    bits the candidate sets in its window (for a 3 x 3 tile of a border prior, 3 cells of an edge
    neighbour, 1 of a corner one), so it is memoised per such sub-configuration: a neighbour costs at
    most ``2^shared`` lookups per update, however many candidates there are."""
    _bit_of, _touch, base, seg, pr_off, pr_pb, pr_wb, memo_off, memo = ts
    dense, db, sp = lp.dense, lp.dense_bits, sparse_table(lp)
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
                    v = _factor(dense, db, sp, seg[q], key)
                    memo[mo + sub] = v
            else:
                v = _factor(dense, db, sp, seg[q], key)
            s += v
            if s == -np.inf:
                break
        out[j] = s


@njit_shipped(inline="always")
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


@njit_shipped
def _tile_cell_log_odds_sparse(lp, k, m):
    s1, s0 = _tile_cell_terms(lp, k, m, False)
    return s1 - s0


@njit_shipped(inline="always")
def tile_cell_log_odds(lp, k, m):
    """:func:`cell_log_odds` of a tiles prior: the factors of the tiles whose window holds ``k``."""
    if lp.dense_bits < 0:
        return _tile_cell_log_odds_sparse(lp, k, m)
    s1, s0 = _tile_cell_terms(lp, k, m, True)
    return s1 - s0


@njit_shipped(inline="always")
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


@njit_shipped(inline="always")
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


@njit_shipped
def tiles_log_prob_batch(lp, maps, out):
    """``sum_t log phi_t(m)`` for every row of ``maps`` (``B x K`` uint8)."""
    T = lp.t_rows * lp.t_cols
    for b in range(maps.shape[0]):
        s = 0.0
        for t in range(T):
            s += tile_log_factor(lp, t, maps[b])
        out[b] = s


@njit_shipped
def tiles_patch_weights(lp, patch, m, cands, n, out, ts):
    """``out[j] = log p(patch = cands[j], rest)`` up to a constant in ``j``: the factors of the tiles whose
    window holds a patch cell, through the scratch ``ts``."""
    for j in range(n):
        out[j] = 0.0
    nt = tile_patch_setup(lp, patch, m, np.int64(-1), ts)
    tile_patch_factors(lp, nt, ts, cands, n, out)


@njit_shipped(inline="always")
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


@njit_shipped(inline="always")
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


@njit_shipped
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


@njit_shipped
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
