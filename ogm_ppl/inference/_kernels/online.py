r"""Compiled parts of the online chain (:mod:`ogm_ppl.inference.online`): a single-cell sweep state whose
ray index grows in place.

The state is the one of :mod:`~ogm_ppl.inference._kernels.cell_sweep` (map ``m``, every ray's first and
second hits ``f_r < s_r``, every cell's kept fixed-point sum ``d_k = sum_r c_r(kappa_r(k))`` of Eq. 2.4 /
4.2 and its counts of infinite terms), with two changes that let rays be appended without rebuilding:

* The ray side (``offsets``, ``cells``, ``ll``, ``rays``) is stored with spare capacity: the first ``R``
  rays are live, the rest is room for more (the Python side doubles the arrays when full). The likelihood
  table is *ragged*: ray ``r``'s ``len(r) + 1`` entries ``log p(z_r | f = kappa)``, ``kappa = 0..len(r)``
  (the last: no hit), lie at ``ll[offsets[r] + r + kappa]``, so the table takes ``nnz + R`` floats instead
  of the ``R x (max len + 1)`` of the offline table.
* The transposed index cell -> (ray, kappa) is a *pool* of per-cell blocks: cell ``k``'s entries are
  ``c_ray[c_start[k] : c_start[k] + c_len[k]]`` (and ``c_kappa``), in a block of ``c_cap[k]`` slots. A cell
  whose block is full moves to a new block of twice the size at the end of the pool; when the pool is full
  it is compacted (live blocks copied in cell order, each with its grown capacity) into a pool of twice the
  capacity it then needs. Since ``c_cap[k] < 2 c_len[k] + 4``, the pool holds at most
  ``2 (2 nnz + 4 K_t)`` slots (``K_t``: cells some ray crosses) of two int32, i.e. memory linear in ``nnz``.

Entries are appended in ray order, so each cell's list stays ordered by ray as in
:class:`~ogm_ppl.raycast.CellIndex`. The updates are those of the offline kernel (``_add_term``,
``_ray_term``, ``_retarget``, ``_lik_ratio`` of :mod:`~ogm_ppl.inference._kernels.cell_sweep`, the same
fixed-point arithmetic) with the ragged table read in place of the dense one, so a state reached online
equals, entry for entry, the offline state of the same map and rays at the same scale.
"""

from __future__ import annotations

from typing import NamedTuple

import numba as nb
import numpy as np

from ogm_ppl._numba_cache import njit_shipped
from ogm_ppl.inference._kernels import cell_sweep as cs
from ogm_ppl.inference._kernels.cells import _next_occupied
from ogm_ppl.priors.compiled import cell_log_odds

#: the smallest block a cell gets in the pool
MIN_BLOCK = 4
#: the signs of a term added / taken away, typed int64 where they are passed: a literal ``1`` / ``-1`` would have
#: numba compile ``_add_term`` and ``_ray_term`` once per value
PLUS = np.int64(1)
MINUS = np.int64(-1)


class OnlineState(NamedTuple):
    """The growing single-cell state (module docstring); rays ``0..R-1`` are live."""

    m: np.ndarray  # K uint8: the map
    rays: np.ndarray  # >= R RAY records: first and second occupied kappa
    d: np.ndarray  # K int64: fixed-point sums of each cell's finite terms
    inf: np.ndarray  # K INF records: counts of each cell's infinite terms (kept only if any_inf)
    any_inf: bool  # whether an entry a live ray uses is -inf
    offsets: np.ndarray  # >= R + 1 int64: CSR along rays
    cells: np.ndarray  # >= nnz int64: cells of each ray in kappa order
    c_start: np.ndarray  # K int64: where cell k's block starts in the pool
    c_len: np.ndarray  # K int64: live entries of cell k
    c_cap: np.ndarray  # K int64: slots of cell k's block
    c_ray: np.ndarray  # pool int32: ray of each entry
    c_kappa: np.ndarray  # pool int32: the cell's position on that ray
    ll: np.ndarray  # >= nnz + R float64, ragged: log p(z_r | first hit at kappa) at offsets[r] + r + kappa
    scale: float  # 2^S: a finite entry x counts as rint(x * scale)


@nb.njit(cache=True)
def _grown(cap, need):
    c = max(cap, MIN_BLOCK)
    while c < need:
        c *= 2
    return c


@nb.njit(cache=True, inline="always")
def _ll(st, r, x):
    return st.ll[st.offsets[r] + r + x]


@nb.njit(cache=True)
def _add_term(st, c, r, x, y, sign):
    """``d_c += sign * (ll[r, x] - ll[r, y])`` in fixed point (or the count of an infinite term)."""
    a = _ll(st, r, x)
    b = _ll(st, r, y)
    if not st.any_inf:
        st.d[c] += sign * (cs._q(a, st.scale) - cs._q(b, st.scale))
    elif a > -np.inf:
        if b > -np.inf:
            st.d[c] += sign * (cs._q(a, st.scale) - cs._q(b, st.scale))
        else:
            st.inf[c].pos += sign
    elif b > -np.inf:
        st.inf[c].neg += sign


@nb.njit(cache=True)
def _ray_term(st, r, kap, f, s, sign):
    """Add ``sign * c_r(kap)`` for a ray whose first and second hits are ``f``, ``s``."""
    c = st.cells[st.offsets[r] + kap]
    if kap < f:
        _add_term(st, c, r, kap, f, sign)
    elif kap == f:
        _add_term(st, c, r, f, s, sign)


@nb.njit(cache=True)
def _retarget(st, r, f1, s1):
    """Move ray ``r``'s first / second hits to ``f1``, ``s1``, updating the kept sums of the cells it reaches."""
    f0 = st.rays[r].f
    s0 = st.rays[r].s
    st.rays[r].f = f1
    st.rays[r].s = s1
    a = st.offsets[r]
    n = st.offsets[r + 1] - a
    if f0 == f1:
        if s0 != s1 and f0 < n:
            c = st.cells[a + f0]
            _add_term(st, c, r, f0, s1, PLUS)
            _add_term(st, c, r, f0, s0, MINUS)
        return
    lo = min(f0, f1)
    b0 = _ll(st, r, f0)
    b1 = _ll(st, r, f1)
    if not st.any_inf:
        delta = cs._q(b0, st.scale) - cs._q(b1, st.scale)
        for kap in range(lo):
            st.d[st.cells[a + kap]] += delta
    elif b0 > -np.inf and b1 > -np.inf:
        delta = cs._q(b0, st.scale) - cs._q(b1, st.scale)
        for kap in range(lo):
            if _ll(st, r, kap) > -np.inf:
                st.d[st.cells[a + kap]] += delta
    else:
        for kap in range(lo):
            c = st.cells[a + kap]
            _add_term(st, c, r, kap, f1, PLUS)
            _add_term(st, c, r, kap, f0, MINUS)
    for kap in range(lo, min(max(f0, f1), n - 1) + 1):
        _ray_term(st, r, kap, f1, s1, PLUS)
        _ray_term(st, r, kap, f0, s0, MINUS)


@nb.njit(cache=True)
def add_cell_entries(st, used, offsets, cells, r0, r1, need):
    """Append the (ray, kappa) entries of rays ``r0..r1-1`` of the ray CSR ``offsets`` / ``cells`` to the
    pool of the :class:`OnlineState` ``st`` (its ``c_start``, ``c_len``, ``c_cap``, ``c_ray``, ``c_kappa``;
    ``used`` of its slots taken; module docstring), growing blocks and, when full, compacting the pool.
    Updates ``st.c_start``, ``st.c_len``, ``st.c_cap`` in place; returns the (possibly new) ``c_ray``,
    ``c_kappa`` and the pool's used length. ``need`` (``K`` int64, all zero) is scratch, left all zero: the
    work is in the new entries and the blocks they grow (the whole grid only when the pool is compacted),
    blocks moved in increasing cell order."""
    c_start, c_len, c_cap, c_ray, c_kappa = st.c_start, st.c_len, st.c_cap, st.c_ray, st.c_kappa
    K = c_start.shape[0]
    e0, e1 = offsets[r0], offsets[r1]
    touched = np.empty(e1 - e0, np.int64)
    nt = 0
    for p in range(e0, e1):
        c = cells[p]
        if need[c] == 0:
            touched[nt] = c
            nt += 1
        need[c] += 1
    touched = np.sort(touched[:nt])
    extra = 0
    for i in range(nt):
        k = touched[i]
        if c_len[k] + need[k] > c_cap[k]:
            extra += _grown(c_cap[k], c_len[k] + need[k])
    if used + extra > c_ray.shape[0]:  # compact into a pool of twice the capacity now needed
        total = 0
        for k in range(K):
            if need[k] > 0 and c_len[k] + need[k] > c_cap[k]:
                total += _grown(c_cap[k], c_len[k] + need[k])
            else:
                total += c_cap[k]
        size = max(2 * total, 1024)
        nr = np.empty(size, np.int32)
        nk = np.empty(size, np.int32)
        pos = 0
        for k in range(K):
            cap = c_cap[k]
            if need[k] > 0 and c_len[k] + need[k] > cap:
                cap = _grown(cap, c_len[k] + need[k])
            a = c_start[k]
            for i in range(c_len[k]):
                nr[pos + i] = c_ray[a + i]
                nk[pos + i] = c_kappa[a + i]
            c_start[k] = pos
            c_cap[k] = cap
            pos += cap
        c_ray, c_kappa, used = nr, nk, pos
    else:  # move the full blocks to the end of the pool
        for i in range(nt):
            k = touched[i]
            if c_len[k] + need[k] > c_cap[k]:
                cap = _grown(c_cap[k], c_len[k] + need[k])
                a = c_start[k]
                for j in range(c_len[k]):
                    c_ray[used + j] = c_ray[a + j]
                    c_kappa[used + j] = c_kappa[a + j]
                c_start[k] = used
                c_cap[k] = cap
                used += cap
    for r in range(r0, r1):
        a = offsets[r]
        for j in range(offsets[r + 1] - a):
            c = cells[a + j]
            q = c_start[c] + c_len[c]
            c_ray[q] = r
            c_kappa[q] = j
            c_len[c] += 1
    for i in range(nt):
        need[touched[i]] = 0
    return c_ray, c_kappa, used


@nb.njit(cache=True)
def add_ray_terms(st, r0, r1):
    """First / second hits of rays ``r0..r1-1`` at the current map and their terms ``c_r(kappa)`` added to
    the kept sums of the cells they reach (the rays must be in the cell index already)."""
    for r in range(r0, r1):
        n = st.offsets[r + 1] - st.offsets[r]
        f = _next_occupied(st.m, st.offsets, st.cells, r, 0)
        s = _next_occupied(st.m, st.offsets, st.cells, r, f + 1) if f < n else n
        st.rays[r].f = f
        st.rays[r].s = s
        for kap in range(min(f, n - 1) + 1):
            _ray_term(st, r, kap, f, s, PLUS)


@nb.njit(cache=True)
def refill_sums(st, R):
    """Recompute every kept sum from scratch at ``st.scale`` (after a change of the fixed-point scale);
    the first / second hits are kept."""
    st.d[:] = 0
    for k in range(st.inf.shape[0]):
        st.inf[k].pos = 0
        st.inf[k].neg = 0
    for r in range(R):
        n = st.offsets[r + 1] - st.offsets[r]
        f = st.rays[r].f
        s = st.rays[r].s
        for kap in range(min(f, n - 1) + 1):
            _ray_term(st, r, kap, f, s, PLUS)


@nb.njit(cache=True)
def any_impossible(ll, offsets, r0, r1):
    """Whether an entry of the ragged table of rays ``r0..r1-1`` is ``-inf``."""
    for p in range(offsets[r0] + r0, offsets[r1] + r1):
        if ll[p] == -np.inf:
            return True
    return False


@nb.njit(cache=True)
def _set_cell(st, k, v):
    """``m[k] = v`` with every ray's hits and every kept sum in step (as ``cell_sweep._set_cell``)."""
    st.m[k] = v
    a = st.c_start[k]
    for p in range(a, a + st.c_len[k]):
        r = np.int64(st.c_ray[p])
        kap = np.int64(st.c_kappa[p])
        f = st.rays[r].f
        s = st.rays[r].s
        if v:
            if kap < f:
                _retarget(st, r, kap, f)
            elif kap < s:
                _retarget(st, r, f, kap)
        elif kap == f:
            n = st.offsets[r + 1] - st.offsets[r]
            _retarget(st, r, s, _next_occupied(st.m, st.offsets, st.cells, r, s + 1) if s < n else n)
        elif kap == s:
            _retarget(st, r, f, _next_occupied(st.m, st.offsets, st.cells, r, kap + 1))


@nb.njit(cache=True)
def set_cell(st, k, v):
    """``m[k] = v`` (no-op if it already is), keeping the state in step."""
    if st.m[k] != v:
        _set_cell(st, k, v)


@nb.njit(cache=True)
def set_cells(st, cells, values):
    """:func:`set_cell` of each ``cells[i]`` to ``values[i]``, in order."""
    for i in range(cells.shape[0]):
        set_cell(st, cells[i], values[i])


@nb.njit(cache=True)
def log_lik_ratio(st, k):
    """``log p(z | m_k = 1, m_-k) - log p(z | m_k = 0, m_-k)`` from the kept sum (as the offline kernel)."""
    return cs._lik_ratio(st, k)


@njit_shipped(_nrt=False)
def sweep(st, order, prior, uniforms, update):
    """One pass of single-cell updates over ``order`` with the compiled prior bundle ``prior`` (heat bath
    or metropolised, :func:`~ogm_ppl.inference._kernels.cell_sweep.new_value`). Returns the flips."""
    flips = 0
    m = st.m
    for i in range(order.shape[0]):
        k = order[i]
        lo = cell_log_odds(prior, k, m)
        lo += cs._lik_ratio(st, k)
        cur = m[k]
        v = cs.new_value(lo, uniforms[i], cur, update)
        if v != cur:
            _set_cell(st, k, v)
            flips += 1
    return flips


@njit_shipped
def sweep_accumulate(st, order, prior, uniforms, update, acc):
    """:func:`sweep`, then ``acc += m`` (the running sum of the marginals). Returns the flips."""
    flips = sweep(st, order, prior, uniforms, update)
    for k in range(acc.shape[0]):
        acc[k] += st.m[k]
    return flips


@nb.njit(cache=True)
def dilate(mask, rows, cols, margin):
    """Cells within Chebyshev distance ``margin`` of a cell of ``mask`` (``rows * cols`` bool), as sorted
    indices: the focus region of the cells the new rays cross."""
    out = np.zeros(rows * cols, np.bool_)
    for k in range(rows * cols):
        if mask[k]:
            r = k // cols
            c = k - r * cols
            for i in range(max(0, r - margin), min(rows, r + margin + 1)):
                for j in range(max(0, c - margin), min(cols, c + margin + 1)):
                    out[i * cols + j] = True
    return np.flatnonzero(out)
