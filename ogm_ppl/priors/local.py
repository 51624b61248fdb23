r"""Local conditionals of correlated priors, in a form compiled kernels read (Chapter 5, Eq. 5.1).

A Gibbs sweep must never evaluate a prior's whole-map ``log_prob`` per update. Priors that want the
compiled path describe themselves by one :class:`LocalPrior` bundle of arrays (a ``typing.NamedTuple``,
which numba takes as one argument). Two families cover Chapter 5:

* **stencil** (``kind = STENCIL``): a pairwise binary field on a neighbourhood stencil,

  .. math:: \log \tilde p(m) = \sum_k m_k \Big(h_k + \sum_{d:\,k+d \in G} a_d\Big)
            + \tfrac12 \sum_k \sum_{d:\,k+d \in G} J_d\, m_k m_{k+d},

  so that the conditional log-odds of a cell is affine in its neighbours,
  ``l(m_k | m_-k) = h_k + sum_{d: k+d in G} (a_d + J_d m_{k+d})`` (``J_d = J_{-d}``). The MRF of
  Section 5.2.1 is ``a_d = log psi``, ``J_d = -2 log psi``: ``l = l(lambda) + (n0 - n1) log psi``.
* **tiles** (``kind = TILES``): ``log p~(m) = sum_t log phi(key_t(m))`` over the tiles ``t`` of a fixed
  tiling of the plane by ``h x w`` rectangles; ``key_t`` packs the tile's *window* (the tile and a ring
  of ``pad`` border cells) into an integer: bit ``i`` = window cell ``i``, the tile's own cells first
  (row-major), then the border ring (row-major in the window). Window cells off the grid read as the
  tile's ``fill`` bits. ``phi`` is a sparse table (sorted keys and their log values) per *segment*; a
  tile names its segment (e.g. the marginal table of tiles cut by the grid edge). Keys missing from a
  segment fall back to segment ``fallback`` (keyed by the tile's own bits only) when its border is
  unseen, else have ``phi = 0``. The patch tables of Section 5.2.2 (``pad = 0``) and the
  border-conditioned tables of Section 5.2.3 (``pad = 1``) are both of this kind.

The numba functions below are the only place the kernels look at a prior: :func:`cell_log_odds`
(single-cell Gibbs, ICM) and :func:`patch_prior_weights` / :func:`tile_candidates` (patch Gibbs, with
sparse enumeration of the configurations a table allows given the border). For speed, tables over
windows of at most 16 cells are also stored dense (one load per factor), and a patch update reads the
keys of the tiles it touches once (:func:`tile_patch_setup`), after which a candidate only ORs in its
own bits and each touched tile's factor is memoised per the few bits the patch sets in it
(:func:`tile_patch_factors`).

A researcher's own prior reaches the compiled path by describing itself as a stencil
(:class:`~ogm_ppl.priors.StencilPrior`: unary weights + pairwise weights per offset) or as tiles
(subclass :class:`TiledPrior` with arrays); a prior with only ``log_prob`` still works through the
generic (slow) path.
"""

from __future__ import annotations

from typing import NamedTuple

import numba as nb
import numpy as np

from ogm_ppl.priors.base import MapPrior

__all__ = ["LocalPrior", "LocalMapPrior", "TileScratch", "STENCIL", "TILES", "cell_log_odds",
           "patch_prior_weights", "tile_candidates", "tile_patch_setup", "tile_patch_factors", "local_of"]  # fmt: skip

STENCIL, TILES = 0, 1
_I = np.zeros(0, np.int64)
_F = np.zeros(0, np.float64)
#: windows of at most this many cells get a dense factor table (at most DENSE_MAX_ENTRIES entries in all)
DENSE_MAX_BITS, DENSE_MAX_ENTRIES = 16, 1 << 20


class LocalPrior(NamedTuple):
    """The arrays a compiled kernel reads (see the module docstring). Unused fields are empty."""

    kind: int
    rows: int
    cols: int
    # stencil
    unary: np.ndarray  # K float64, h_k
    s_dr: np.ndarray  # D int64
    s_dc: np.ndarray  # D int64
    s_bias: np.ndarray  # D float64, a_d
    s_coup: np.ndarray  # D float64, J_d
    # tiles
    w_dr: np.ndarray  # Lw int64: window offsets from the tile anchor (tile cells first)
    w_dc: np.ndarray
    n_inner: int  # cells of a tile (h * w)
    t_h: int
    t_w: int
    t_r0: int  # anchor (top-left cell) of tile (0, 0); <= 0
    t_c0: int
    t_rows: int  # tiles per column / row
    t_cols: int
    pad_r: int
    pad_c: int
    t_seg: np.ndarray  # T int64: segment of each tile
    t_fill: np.ndarray  # T int64: key bits of window cells off the grid
    seg_off: np.ndarray  # S + 1 int64
    keys: np.ndarray  # sorted within each segment
    logp: np.ndarray
    fallback: int  # segment used for unseen borders (-1: none, phi = 0)
    # the same factors as a dense table, for small windows: dense[s << dense_bits | key] = log phi(key) in
    # segment s (fallback resolved), so a lookup is one load instead of a binary search
    dense: np.ndarray  # S * 2^Lw float64 (empty: none)
    dense_bits: int  # Lw when ``dense`` is present, else -1


def stencil_local(rows, cols, unary, dr, dc, bias, coup) -> LocalPrior:
    """A :class:`LocalPrior` of the stencil kind."""
    return LocalPrior(STENCIL, int(rows), int(cols), np.ascontiguousarray(unary, np.float64),
                      np.ascontiguousarray(dr, np.int64), np.ascontiguousarray(dc, np.int64),
                      np.ascontiguousarray(bias, np.float64), np.ascontiguousarray(coup, np.float64),
                      _I, _I, 0, 1, 1, 0, 0, 0, 0, 0, 0, _I, _I, np.zeros(1, np.int64), _I, _F, -1, _F, -1)  # fmt: skip


def local_of(prior) -> LocalPrior | None:
    """The prior's :class:`LocalPrior` (``prior.local()``), or ``None`` for priors without one."""
    fn = getattr(prior, "local", None)
    return fn() if callable(fn) else None


# ------------------------------------------------------------------ stencil
@nb.njit(cache=True, inline="always")
def stencil_cell_log_odds(lp, k, m):
    """``l(m_k | m_-k) = h_k + sum_{d in grid} (a_d + J_d m_{k+d})``."""
    s_dr, s_dc, s_bias, s_coup = lp.s_dr, lp.s_dc, lp.s_bias, lp.s_coup
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


# ------------------------------------------------------------------ tiles
# Speed: the hot helpers are inlined (``inline="always"``; a call that passes the LocalPrior bundle costs
# about 130 ns in reference counts of its arrays, more than a lookup itself), and each binds the bundle's
# arrays to locals once (numba counts a reference at every ``lp.array`` read: in a loop that costs 5x).
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
    for i in range(w_dr.shape[0]):
        r = ar + w_dr[i]
        c = ac + w_dc[i]
        if 0 <= r < rows and 0 <= c < cols and m[r * cols + c]:
            key |= np.int64(1) << i
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


@nb.njit(cache=True)
def _sparse_factor(keys, logp, seg_off, backoff, n_inner, s, key):
    """``log phi(key)`` in segment ``s`` by binary search of the sorted keys, backing off to segment
    ``backoff`` (keyed by the inner bits; ``-1``: none) when the key's border was never seen; ``-inf`` if
    absent. (Not inlined: a large inlined body slows the loops around it.)"""
    a, b = seg_off[s], seg_off[s + 1]
    i = _lower(keys, a, b, key)
    if i < b and keys[i] == key:
        return logp[i]
    if backoff >= 0:
        border = key >> n_inner
        j = _lower(keys, a, b, border << n_inner)
        if j == b or (keys[j] >> n_inner) != border:  # border never seen: back off
            fa, fb = seg_off[backoff], seg_off[backoff + 1]
            inner = key & ((np.int64(1) << n_inner) - 1)
            q = _lower(keys, fa, fb, inner)
            if q < fb and keys[q] == inner:
                return logp[q]
    return -np.inf


@nb.njit(cache=True, inline="always")
def _factor(dense, dense_bits, keys, logp, seg_off, backoff, n_inner, s, key):
    """``log phi(key)`` in segment ``s`` from arrays already bound to locals: one load from the dense table
    if ``dense_bits >= 0``, else :func:`_sparse_factor`."""
    if dense_bits >= 0:
        return dense[(s << dense_bits) | key]
    return _sparse_factor(keys, logp, seg_off, backoff, n_inner, s, key)


@nb.njit(cache=True, inline="always")
def _backoff(lp):
    """The fallback segment when keys have a border to back off from, else ``-1``."""
    return lp.fallback if lp.w_dr.shape[0] > lp.n_inner else -1


@nb.njit(cache=True, inline="always")
def sparse_key_log_factor(lp, s, key):
    """``log phi(key)`` in segment ``s`` from the sorted keys (fallback for an unseen border; ``-inf`` if
    absent)."""
    return _factor(lp.dense, -1, lp.keys, lp.logp, lp.seg_off, _backoff(lp), lp.n_inner, s, key)


@nb.njit(cache=True, inline="always")
def key_log_factor(lp, s, key):
    """``log phi(key)`` in segment ``s``: one load from the dense table when there is one, else
    :func:`sparse_key_log_factor`."""
    return _factor(lp.dense, lp.dense_bits, lp.keys, lp.logp, lp.seg_off, _backoff(lp), lp.n_inner, s, key)


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


#: a touched tile's factor is memoised per sub-configuration when it shares at most this many patch cells
MEMO_BITS = 10


class TileScratch(NamedTuple):
    """Scratch of :func:`tile_patch_setup` / :func:`tile_patch_factors`, allocated once per sweep by
    :func:`tile_scratch` (``C``: :func:`touch_capacity`)."""

    bit_of: np.ndarray  # K int64, all -1 between updates: the patch bit of a cell
    touch: np.ndarray  # C int64: touched tiles
    base: np.ndarray  # C int64: their window keys with the patch cells read as free
    seg: np.ndarray  # C int64: their segments
    pr_off: np.ndarray  # C + 1 int64: pairs of tile q are pr_off[q]:pr_off[q + 1]
    pr_pb: np.ndarray  # C int64: patch bit of a pair
    pr_wb: np.ndarray  # C int64: window bit of a pair
    memo_off: np.ndarray  # C + 1 int64: start of tile q's memo (-1: not memoised); memo_off[nt] = size
    memo: np.ndarray  # C << MEMO_BITS float64: factor per sub-configuration (nan: not yet computed)


@nb.njit(cache=True)
def tile_scratch(lp, num_cells, L):
    C = touch_capacity(lp, L) if lp.kind == TILES else 1
    return TileScratch(np.full(num_cells, -1, np.int64), np.empty(C, np.int64), np.empty(C, np.int64),
                       np.empty(C, np.int64), np.empty(C + 1, np.int64), np.empty(C, np.int64),
                       np.empty(C, np.int64), np.empty(C + 1, np.int64),
                       np.empty(C << MEMO_BITS, np.float64))  # fmt: skip


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
    backoff, n_inner = _backoff(lp), lp.n_inner
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
                    v = _factor(dense, db, keys, logp, seg_off, backoff, n_inner, seg[q], key)
                    memo[mo + sub] = v
            else:
                v = _factor(dense, db, keys, logp, seg_off, backoff, n_inner, seg[q], key)
            s += v
            if s == -np.inf:
                break
        out[j] = s


# ------------------------------------------------------------------ shared entry points
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
def cell_log_odds(lp, k, m):
    """``log p(m_k = 1, m_-k) - log p(m_k = 0, m_-k)`` under the prior (``nan`` if both are impossible)."""
    if lp.kind == STENCIL:
        return stencil_cell_log_odds(lp, k, m)
    return tile_cell_log_odds(lp, k, m)


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
            for d in range(lp.s_dr.shape[0]):
                if ry - rx == lp.s_dr[d] and cy - cx == lp.s_dc[d]:
                    pi[npair] = x
                    pj[npair] = y
                    pw[npair] = lp.s_coup[d]
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


@nb.njit(cache=True)
def patch_prior_weights_ws(lp, patch, m, cands, n, out, ts):
    """:func:`patch_prior_weights` with the tile scratch ``ts`` of :func:`tile_scratch` (no allocation
    for tiles priors)."""
    if lp.kind == STENCIL:
        stencil_patch_weights(lp, patch, m, cands, n, out)
        return
    for j in range(n):
        out[j] = 0.0
    nt = tile_patch_setup(lp, patch, m, -1, ts)
    tile_patch_factors(lp, nt, ts, cands, n, out)


@nb.njit(cache=True)
def patch_prior_weights(lp, patch, m, cands, n, out):
    """``out[j] = log p(patch = cands[j], rest)`` up to a constant in ``j`` (bit ``b`` of a candidate =
    the ``b``-th live cell of ``patch``; ``-1`` entries are not part of the patch). ``m`` is unchanged."""
    patch_prior_weights_ws(lp, patch, m, cands, n, out, tile_scratch(lp, m.shape[0], patch.shape[0]))


@nb.njit(cache=True, inline="always")
def tile_of_anchor(lp, r0, c0, h, w):
    """The tile whose cells are exactly the ``h x w`` rectangle at ``(r0, c0)``, or ``-1``."""
    if lp.kind != TILES or h != lp.t_h or w != lp.t_w:
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
    a, b = seg_off[s], seg_off[s + 1]
    lo = _lower(keys, a, b, border << Li)
    hi = _lower(keys, a, b, (border + 1) << Li)
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
    n = 0
    for q in range(lo, hi):
        inner = keys[q] & ((np.int64(1) << Li) - 1)
        ok = True
        code = 0
        bit = 0
        if live == Li:  # every tile cell is live: the code is the inner key itself
            code = inner
        else:
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
def prior_gibbs_sweeps(lp, maps, num_sweeps, seed):
    """Single-cell Gibbs sweeps on the prior alone, for each row of ``maps`` (``B x K`` uint8), in place."""
    np.random.seed(seed)
    for b in range(maps.shape[0]):
        m = maps[b]
        for _ in range(num_sweeps):
            for k in range(m.shape[0]):
                lo = cell_log_odds(lp, k, m)
                if lo != lo:
                    continue
                u = np.random.random()
                if lo >= 0:
                    m[k] = 1 if u * (1.0 + np.exp(-lo)) < 1.0 else 0
                else:
                    e = np.exp(lo)
                    m[k] = 1 if u * (1.0 + e) < e else 0


@nb.njit(cache=True)
def patch_prior_batch(lp, maps, patch, cands, out):
    """:func:`patch_prior_weights` for every row of ``maps`` (``B x K`` uint8) -> ``out`` (``B x W``)."""
    ts = tile_scratch(lp, maps.shape[1], patch.shape[0])
    for b in range(maps.shape[0]):
        patch_prior_weights_ws(lp, patch, maps[b], cands, cands.shape[0], out[b], ts)


@nb.njit(cache=True)
def tiles_log_prob_batch(lp, maps, out):
    """``sum_t log phi_t(m)`` for every row of ``maps`` (``B x K`` uint8)."""
    T = lp.t_rows * lp.t_cols
    for b in range(maps.shape[0]):
        s = 0.0
        for t in range(T):
            s += tile_log_factor(lp, t, maps[b])
        out[b] = s

# ------------------------------------------------------------------ Python side
def grid_shape(shape) -> tuple[int, int, int]:
    """``(rows, cols, ndim)`` of a grid shape ``K``, ``(K,)`` or ``(rows, cols)`` (or a Grid)."""
    shape = getattr(shape, "shape", shape)
    if np.isscalar(shape):
        shape = (int(shape),)  # type: ignore[arg-type]  # numpy's isscalar TypeGuard narrows to generic | complex | bytes
    shape = tuple(int(s) for s in shape)
    if len(shape) == 1:
        return 1, shape[0], 1
    if len(shape) == 2:
        return shape[0], shape[1], 2
    raise ValueError(f"grid shape must be (K,) or (rows, cols), got {shape}")


class LocalMapPrior(MapPrior):
    """Mixin of priors with a compiled local conditional (:meth:`local`): the patch conditional
    :meth:`log_prob_patch` and prior sampling both run through the same compiled functions the Gibbs
    kernels call. Subclasses set ``rows, cols, ndim, num_cells`` and build ``self._local``."""

    #: ``log_prob`` is exact (``True``) or known only up to the log partition function (``False``).
    normalised = True
    _local: LocalPrior

    def local(self) -> LocalPrior:
        """The :class:`LocalPrior` bundle the compiled kernels read."""
        return self._local

    def cell_log_odds(self):
        return None

    def log_prob_patch(self, maps, cells, configs):
        import torch

        maps = torch.as_tensor(maps)
        squeeze = maps.dim() == 1
        mm = np.ascontiguousarray(maps.reshape(-1, self.num_cells).detach().cpu().numpy() != 0, dtype=np.uint8)
        patch = np.ascontiguousarray(torch.as_tensor(cells).numpy(), dtype=np.int64)
        cf = torch.as_tensor(configs).detach().cpu().numpy().reshape(-1, len(patch)) != 0
        cands = np.ascontiguousarray((cf.astype(np.int64) << np.arange(len(patch))).sum(1), dtype=np.int64)
        out = np.empty((mm.shape[0], len(cands)), np.float64)
        patch_prior_batch(self._local, mm, patch, cands, out)
        res = torch.from_numpy(out)
        return res[0] if squeeze else res

    def log_normaliser(self, max_cells: int = 22) -> float:
        """``log Z`` by enumeration of all ``2^K`` maps (small maps only; 0 for normalised priors)."""
        import torch

        if self.normalised:
            return 0.0
        K = self.num_cells
        if K > max_cells:
            raise ValueError(f"log_normaliser enumerates 2^{K} maps; the limit is max_cells = {max_cells}")
        codes = torch.arange(2**K)
        maps = ((codes[:, None] >> torch.arange(K)) & 1).to(torch.float64)
        return float(torch.logsumexp(self.log_prob(maps), 0))

    def _gibbs_sample(self, sample_shape, generator, num_sweeps: int):
        import torch

        shape = torch.Size(sample_shape)
        B = int(np.prod(shape)) if len(shape) else 1
        u = torch.rand((B, self.num_cells), generator=generator, dtype=torch.float64)
        maps = np.ascontiguousarray((u < 0.5).numpy(), dtype=np.uint8)
        seed = int(torch.randint(0, 2**31 - 1, (1,), generator=generator))
        prior_gibbs_sweeps(self._local, maps, int(num_sweeps), seed)
        return torch.from_numpy(maps.astype(np.float64)).reshape(*shape, self.num_cells)


def tiling(rows: int, cols: int, tile, pad, origin):
    """Geometry of a tiling of a ``rows x cols`` grid by ``h x w`` tiles, one of which has its top-left
    cell at ``origin``, with windows padded by ``pad = (pr, pc)``. Returns ``(w_dr, w_dc, t_r0, t_c0,
    t_rows, t_cols, off_mask)``: window offsets (tile cells row-major first, then the border ring
    row-major) and, per tile, the key bits of its window cells that lie off the grid."""
    h, w = tile
    pr, pc = pad
    inner = [(r, c) for r in range(h) for c in range(w)]
    ring = [(r, c) for r in range(-pr, h + pr) for c in range(-pc, w + pc) if not (0 <= r < h and 0 <= c < w)]
    off = np.array(inner + ring, dtype=np.int64).reshape(-1, 2)
    r0 = int(origin[0]) % h
    c0 = int(origin[1]) % w
    r0 = r0 - h if r0 else 0
    c0 = c0 - w if c0 else 0
    t_rows = -(-(rows - r0) // h)
    t_cols = -(-(cols - c0) // w)
    ti, tj = np.meshgrid(np.arange(t_rows), np.arange(t_cols), indexing="ij")
    ar = (r0 + ti.ravel() * h)[:, None] + off[None, :, 0]
    ac = (c0 + tj.ravel() * w)[:, None] + off[None, :, 1]
    outside = ~((ar >= 0) & (ar < rows) & (ac >= 0) & (ac < cols))
    off_mask = (outside.astype(np.int64) << np.arange(len(off), dtype=np.int64)).sum(1)
    return (np.ascontiguousarray(off[:, 0]), np.ascontiguousarray(off[:, 1]), r0, c0, int(t_rows), int(t_cols),
            np.ascontiguousarray(off_mask, dtype=np.int64))  # fmt: skip


def tiles_local(rows, cols, geometry, n_inner, tile, pad, t_seg, t_fill, seg_keys, seg_logp, fallback=-1):
    """A :class:`LocalPrior` of the tiles kind from per-segment (keys, log-values) lists."""
    w_dr, w_dc, r0, c0, t_rows, t_cols, _ = geometry
    seg_off = np.zeros(len(seg_keys) + 1, np.int64)
    keys, logp = [], []
    for s, (k, lp) in enumerate(zip(seg_keys, seg_logp)):
        order = np.argsort(k, kind="stable")
        keys.append(np.asarray(k, np.int64)[order])
        logp.append(np.asarray(lp, np.float64)[order])
        seg_off[s + 1] = seg_off[s] + len(k)
    keys = np.ascontiguousarray(np.concatenate(keys) if keys else _I, np.int64)
    logp = np.ascontiguousarray(np.concatenate(logp) if logp else _F, np.float64)
    lp = LocalPrior(TILES, int(rows), int(cols), _F, _I, _I, _F, _F, w_dr, w_dc, int(n_inner), int(tile[0]),
                    int(tile[1]), int(r0), int(c0), int(t_rows), int(t_cols), int(pad[0]), int(pad[1]),
                    np.ascontiguousarray(t_seg, np.int64), np.ascontiguousarray(t_fill, np.int64), seg_off,
                    keys, logp, int(fallback), _F, -1)  # fmt: skip
    Lw = len(w_dr)
    if Lw <= DENSE_MAX_BITS and (len(seg_keys) << Lw) <= DENSE_MAX_ENTRIES:
        lp = lp._replace(dense=dense_factor_table(lp), dense_bits=Lw)
    return lp


def tiles_log_prob(prior, maps):
    """``sum_t log phi_t(m)`` for ``... x K`` maps, through the compiled tile lookups."""
    import torch

    maps = torch.as_tensor(maps)
    batch = maps.shape[:-1]
    mm = np.ascontiguousarray(maps.reshape(-1, prior.num_cells).detach().cpu().numpy() != 0, dtype=np.uint8)
    out = np.empty(mm.shape[0], np.float64)
    tiles_log_prob_batch(prior._local, mm, out)
    return torch.from_numpy(out).reshape(batch)
