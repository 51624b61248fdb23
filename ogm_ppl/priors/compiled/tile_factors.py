"""The factor lookups of the tiles kind (:class:`~ogm_ppl.priors.compiled.tiles.Tiles`): a tile's key from the
map, ``log phi(key)`` of a segment (dense table, border index and binary search, back-off and fallback), and the
dense tables built from the sparse ones. Compiled functions that take the bundle ``lp`` by its fields."""

from __future__ import annotations

from typing import NamedTuple

import numba as nb
import numpy as np

from ogm_ppl._numba_cache import njit_shipped

__all__ = [
    "border_index",
    "border_range",
    "dense_factor_table",
    "fallback_dense_table",
    "key_log_factor",
    "sparse_key_log_factor",
    "tile_key",
]


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
@njit_shipped(inline="always")
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


class SparseTable(NamedTuple):
    """The sorted-key lookup of :func:`_sparse_factor`, bound once before a loop of :func:`_factor` (one numba
    argument; the fields of the bundle ``lp`` it reads, with its back-off)."""

    keys: np.ndarray  # int64: each segment's sorted keys
    logp: np.ndarray  # float64: log phi of each key
    seg_off: np.ndarray  # S + 1 int64: where each segment's keys start
    backoff: int  # the fallback segment of an unseen border, or -1 (:func:`_backoff`)
    bseg: int  # the border-weight segment of a backed-off table, or -1
    n_inner: int  # a key's inner bits (below its border code)
    b_start: np.ndarray  # int64: the border index (:func:`border_index`)
    b_bits: int  # border bits of that index, or -1 if none


@njit_shipped(inline="always")
def sparse_table(lp):
    """The :class:`SparseTable` of the bundle ``lp``."""
    return SparseTable(lp.keys, lp.logp, lp.seg_off, _backoff(lp), lp.border_seg, lp.n_inner, lp.b_start, lp.b_bits)


@nb.njit(cache=True, inline="always")
def _factor(dense, dense_bits, sp, s, key):
    """``log phi(key)`` in segment ``s`` from arrays already bound to locals: one load from the dense table
    if ``dense_bits >= 0``, else :func:`_sparse_factor` of ``sp`` (:class:`SparseTable`)."""
    if dense_bits >= 0:
        return dense[(s << dense_bits) | key]
    keys, logp, seg_off, backoff, bseg, n_inner, b_start, b_bits = sp
    return _sparse_factor(keys, logp, seg_off, backoff, bseg, n_inner, b_start, b_bits, s, key)


@njit_shipped(inline="always")
def _backoff(lp):
    """The fallback segment when keys have a border to back off from, else ``-1``."""
    return lp.fallback if lp.w_dr.shape[0] > lp.n_inner else -1


@njit_shipped(inline="always")
def sparse_key_log_factor(lp, s, key):
    """``log phi(key)`` in segment ``s`` from the sorted keys (fallback for an unseen border; ``-inf`` if
    absent)."""
    return _factor(lp.dense, -1, sparse_table(lp), s, key)


@njit_shipped(inline="always")
def key_log_factor(lp, s, key):
    """``log phi(key)`` in segment ``s``: one load from the dense table when there is one, else
    :func:`sparse_key_log_factor`."""
    return _factor(lp.dense, lp.dense_bits, sparse_table(lp), s, key)


@njit_shipped
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
