"""Compiled single-cell sweeps over one state bundle (Sections 4.1, 4.1.2): heat-bath Gibbs and
metropolised Gibbs, with an independent or a correlated prior.

Data layout, chosen for the sweep's memory traffic (one L = 1 sweep visits every (ray, cell) pair once):

* ``pairs`` (by cell, contiguous per cell): ``(ll, ray, kappa)`` records of 16 bytes, where ``ll`` is
  ``log p(z_ray | first hit at kappa)``, so the likelihood of "this cell is the ray's first hit" streams
  in with the index instead of being looked up in the ``R x (F + 1)`` table;
* ``rays`` (by ray): ``(ll_hit, f)`` records, the ray's first occupied kappa ``f`` and
  ``ll[ray, f]``: the state every pair reads, 16 bytes a ray, so one cache line serves both;
* ``nexts`` (by ray): ``(ll_next, s)`` records, a cache of the ray's *second* occupied kappa ``s`` (the next
  occupied cell after ``f``; ``len(ray)`` if none) and ``ll[ray, s]``, or ``s = -1``: not known. When ``k``
  is a ray's first hit, ``ll_next`` is the likelihood the ray takes without ``k``; the plain way to get it
  walks along the ray (the CSR ``offsets, cells``) and reads the table ``ll``, two cache misses, for about
  0.6 % of a steady-state sweep's pairs in the reference scene (yet a third of the pair loop's time). The cache
  is filled on demand and kept by flips where that is free (a cell occupied in front of the first hit
  makes the old first hit the second; one between the two becomes the second); a flip that frees the
  first or second hit only marks it unknown. The records live apart from ``rays`` so that the hot
  per-ray state stays 16 bytes a ray.

Flipping cell ``k`` costs the rays through ``k`` not blocked before it. The hot loops index with unsigned
integers (numba adds negative-index wraparound code to every signed index; the pair loop ran 1.5x
slower with it), and sum over the pairs without a branch on whether a ray is blocked (about a quarter of
the pairs in the steady state, in no pattern a branch predictor learns), see :func:`_lik_ratio`. Scans that jump about the
map (permutation, random) prefetch the data of the cells a few updates ahead, which the hardware cannot
guess (:func:`_prefetch_ahead`); a systematic scan's streams need no help. :class:`CellState` bundles
the arrays so that compiled code takes one argument.

The log-likelihood ratios are the same floating-point operations in the same order as those of the
straightforward loop (skip blocked rays, add ``ll[r, kappa] - ll[r, f]``, with ``ll[r, next occupied]``
for the ray's first hit), so sweeps are bit-for-bit those of that loop, for every scan and update rule
(``tests/inference/mcmc/test_cell_sweep_layout.py`` keeps a copy of it and checks).

Update rules: ``HEAT_BATH`` draws ``m_k ~ p(m_k | m_-k, z)`` (Eq. 4.2, the thesis's Gibbs);
``METROPOLISED`` proposes the flip and accepts it with ``min(1, p(flip) / p(stay))`` (Liu's metropolised
Gibbs: for a binary cell it moves at least as often as heat bath, so it is no worse in Peskun's order).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba as nb
import numpy as np
from llvmlite import ir
from numba import types
from numba.core import cgutils
from numba.extending import intrinsic

from ogm_ppl.priors.local import STENCIL, TILES, stencil_cell_log_odds, tile_cell_log_odds

HEAT_BATH = 0
METROPOLISED = 1

PAIR = np.dtype([("ll", np.float64), ("ray", np.uint32), ("kappa", np.uint32)], align=True)
RAY = np.dtype([("ll_hit", np.float64), ("f", np.int64)], align=True)
NEXT = np.dtype([("ll_next", np.float64), ("s", np.int64)], align=True)
#: how many cell updates ahead a jumping scan prefetches pair blocks (the per-ray records: half as many)
PREFETCH_AHEAD = 8
# Far from 0, a cell's log-odds decide its update without exp(), bit for bit: for lo > _FAR,
# 1 + exp(-lo) rounds to 1; for lo < -_FAR, exp(lo) <= exp(-40) = 4.25e-18 < _TINY_U, so a uniform
# u >= _TINY_U rejects whatever exp() returns (the same holds for a metropolised flip's log-ratio).
_FAR = 40.0
_TINY_U = 4.3e-18


class CellState(NamedTuple):
    """The map and the per-ray state a single-cell sweep reads and writes, with the index it walks."""

    m: np.ndarray  # K uint8: the map
    rays: np.ndarray  # R RAY records: first occupied kappa f and ll[r, f]
    nexts: np.ndarray  # R NEXT records: second occupied kappa s and ll[r, s], or s = -1 (not known)
    offsets: np.ndarray  # R + 1 int64: CSR along rays
    cells: np.ndarray  # nnz int64: cells of each ray in kappa order
    c_off: np.ndarray  # K + 1 int64: CSR by cell into pairs
    pairs: np.ndarray  # nnz PAIR records, by cell
    ll: np.ndarray  # R x (F + 1) float64: log p(z_r | first hit at kappa); column len(r) = no hit


def pair_index(c_ray: np.ndarray, c_kappa: np.ndarray, ll: np.ndarray) -> np.ndarray:
    """The by-cell ``(ll, ray, kappa)`` records of a model's transposed ray index."""
    if len(c_ray) and (c_ray.max() >= 2**31 or c_kappa.max() >= 2**31):
        raise ValueError("more than 2^31 rays or cells on a ray: the compact index cannot hold them")
    pairs = np.empty(len(c_ray), PAIR)
    pairs["ll"] = ll[c_ray, c_kappa]
    pairs["ray"] = c_ray
    pairs["kappa"] = c_kappa
    return pairs


def ray_state(f: np.ndarray, ll: np.ndarray) -> np.ndarray:
    """``RAY`` records for first hits ``f``."""
    rays = np.empty(len(f), RAY)
    rays["f"] = f
    rays["ll_hit"] = ll[np.arange(len(f)), f]
    return rays


def next_state(m: np.ndarray, f: np.ndarray, offsets: np.ndarray, cells: np.ndarray, ll: np.ndarray) -> np.ndarray:
    """``NEXT`` records of map ``m`` whose rays first hit at ``f``: every ray's next occupied kappa after
    ``f`` (``len(ray)`` if none, and if ``f`` is ``len(ray)``) and its likelihood, all known."""
    nexts = np.empty(len(f), NEXT)
    _fill_nexts(m, np.ascontiguousarray(f, dtype=np.int64), offsets, cells, ll, nexts)
    return nexts


@nb.njit(cache=True)
def _fill_nexts(m, f, offsets, cells, ll, nexts):
    for r in range(f.shape[0]):
        s = _next_occupied_in(m, offsets, cells, r, f[r] + 1)
        nexts[r].s = s
        nexts[r].ll_next = ll[r, s]


@nb.njit(cache=True, inline="always")
def _next_occupied_in(m, offsets, cells, r, start):
    a = offsets[r]
    n = offsets[r + 1] - a
    for j in range(start, n):
        if m[cells[a + j]]:
            return j
    return n


@nb.njit(cache=True, inline="always")
def _next_occupied(st, r, start):
    return _next_occupied_in(st.m, st.offsets, st.cells, r, start)


@intrinsic
def _prefetch(typingctx, arr, idx):
    """Hint the cache to fetch ``arr[idx]`` (LLVM's ``prefetch``: read, keep); no effect on results."""
    sig = types.void(arr, idx)

    def codegen(context, builder, signature, args):
        aty = signature.args[0]
        ary = context.make_array(aty)(context, builder, args[0])
        ptr = cgutils.get_item_pointer(context, builder, aty, ary, [args[1]], wraparound=False, boundscheck=False)
        i8p = ir.IntType(8).as_pointer()
        i32 = ir.IntType(32)
        fn = cgutils.get_or_insert_function(builder.module, ir.FunctionType(ir.VoidType(), [i8p, i32, i32, i32]),
                                            "llvm.prefetch.p0i8")  # fmt: skip
        builder.call(fn, [builder.bitcast(ptr, i8p), ir.Constant(i32, 0), ir.Constant(i32, 3), ir.Constant(i32, 1)])
        return context.get_dummy_value()

    return sig, codegen


@nb.njit(cache=True, inline="always")
def _prefetch_ahead(c_off, m, pairs, rays, order, i, D, extra):
    """Prefetch, at update ``i`` of ``order``, in three stages so that each finds the data it reads in the
    cache: the cell entries of update ``i + 2D`` (``c_off``, the map, ``extra``: the prior's log-odds), the
    pair block of update ``i + D`` and the ray records named by the pairs of update ``i + D // 2``. It takes
    arrays, not the state bundle: inlined, a function of the bundle counts references to every array of
    it at every update."""
    n = order.shape[0]
    if i + 2 * D < n:
        k2 = order[i + 2 * D]
        _prefetch(c_off, k2)
        _prefetch(m, k2)
        _prefetch(extra, k2)
    if i + D < n:
        k1 = order[i + D]
        a = np.uint64(c_off[k1])
        b = np.uint64(c_off[k1 + 1])
        for q in range(a, b, np.uint64(4)):  # 4 records a cache line
            _prefetch(pairs, q)
        if b > a:
            _prefetch(pairs, b - np.uint64(1))
    h = D // 2
    if i + h < n:
        k3 = order[i + h]
        for q in range(np.uint64(c_off[k3]), np.uint64(c_off[k3 + 1])):
            _prefetch(rays, np.uint64(pairs[q].ray))


@nb.njit(cache=True)
def _jumps(order):
    """Whether ``order`` is not ascending (a permutation / random scan): such sweeps prefetch."""
    for i in range(1, order.shape[0]):
        if order[i] < order[i - 1]:
            return True
    return False


@nb.njit(cache=True)
def log_lik_ratio(st, k):
    """``log p(z | m_k = 1, m_-k) - log p(z | m_k = 0, m_-k)`` (Eq. 2.4, 4.2); rays blocked before ``k``
    are skipped, and a difference of two impossible readings (``-inf - -inf``) counts as no preference.
    (May fill the second-hit cache ``st.nexts``.)"""
    return _lik_ratio(st, k)


@nb.njit(cache=True, inline="always")
def _lik_ratio(st, k):
    # The straightforward loop is: skip a ray blocked before k (fr < kappa); else t = ll[r, kappa] - ll[r, f]
    # (ll[r, s] for a first hit) and d += t unless t is nan. Here a blocked ray's t is multiplied by
    # w = 0 instead (w from min / max, which LLVM keeps branch-free; from a comparison it would branch
    # again), and nan (from -inf - -inf, or from inf * 0) is replaced by 0.0. Adding 0.0 leaves d as it
    # is (d starts at +0.0 and so is never -0.0), so d is bit-for-bit the sum of the straightforward loop.
    d = 0.0
    pairs = st.pairs
    rays = st.rays
    for p in range(np.uint64(st.c_off[k]), np.uint64(st.c_off[k + 1])):
        kap = np.int64(pairs[p].kappa)
        r = np.uint64(pairs[p].ray)
        fr = rays[r].f
        if fr == kap:  # k is the ray's first hit: without it the ray runs on to its second hit
            if st.nexts[r].s < 0:
                _refresh_next(st, r, kap + 1)
            t = pairs[p].ll - st.nexts[r].ll_next
        else:  # w = 1 if the ray reaches k (fr > kap), 0 if it is blocked before k
            w = min(max(np.float64(fr - kap), 0.0), 1.0)
            t = (pairs[p].ll - rays[r].ll_hit) * w
        d += t if t == t else 0.0
    return d


@nb.njit(cache=True, inline="always")
def _refresh_next(st, r, start):
    s = _next_occupied(st, r, start)
    st.nexts[r].s = s
    st.nexts[r].ll_next = st.ll[r, s]


@nb.njit(cache=True)
def set_cell(st, k, v):
    """``m[k] = v``, keeping every ray's first hit (and its likelihood) and the second-hit cache in step."""
    if st.m[k] == v:
        return
    _set_cell(st, k, v)


@nb.njit(cache=True, inline="always")
def _set_cell(st, k, v):
    st.m[k] = v
    pairs = st.pairs
    rays = st.rays
    nexts = st.nexts
    for p in range(np.uint64(st.c_off[k]), np.uint64(st.c_off[k + 1])):
        kap = np.int64(pairs[p].kappa)
        r = np.uint64(pairs[p].ray)
        f = rays[r].f
        if v:
            if kap < f:  # the new first hit: the old one is now the second
                nexts[r].s = f
                nexts[r].ll_next = rays[r].ll_hit
                rays[r].f = kap
                rays[r].ll_hit = pairs[p].ll
            elif kap < nexts[r].s:  # the new second hit (an unknown one, -1, stays unknown)
                nexts[r].s = kap
                nexts[r].ll_next = pairs[p].ll
        elif f == kap:  # the first hit freed: the second takes over (searched for if not known)
            s = nexts[r].s
            if s < 0:
                s = _next_occupied(st, r, kap + 1)
                rays[r].ll_hit = st.ll[r, s]
            else:
                rays[r].ll_hit = nexts[r].ll_next
            rays[r].f = s
            nexts[r].s = -1
        elif nexts[r].s == kap:  # the second hit freed
            nexts[r].s = -1


@nb.njit(cache=True, inline="always")
def new_value(lo, u, cur, update):
    """The cell's next value given its conditional log-odds ``lo`` and a uniform ``u``.

    Heat bath: occupied with probability ``sigmoid(lo)``. Metropolised: flip with probability
    ``min(1, exp(+-lo))`` (``+lo`` from free, ``-lo`` from occupied). ``nan`` (both values without prior
    mass, so the state has none) moves by a fair coin so that the chain can leave such a state.
    For ``|lo| > 40`` the answer is decided without ``exp``, bit for bit the same (see ``_FAR``).
    """
    if lo != lo:
        return 1 if u < 0.5 else 0
    if update == METROPOLISED:
        d = -lo if cur else lo  # log p(flip) - log p(stay)
        if d >= 0.0:
            return 1 - cur
        if d < -_FAR and u >= _TINY_U:
            return cur
        if d > -np.inf and u < math.exp(d):
            return 1 - cur
        return cur
    if lo >= 0.0:
        if lo > _FAR:
            return 1 if u < 1.0 else 0
        return 1 if u * (1.0 + math.exp(-lo)) < 1.0 else 0
    if lo < -_FAR and u >= _TINY_U:
        return 0
    e = math.exp(lo)
    return 1 if u * (1.0 + e) < e else 0


@nb.njit(cache=True)
def sweep_independent(st, order, prior_log_odds, uniforms, update):
    """One pass of single-cell updates over ``order`` with an independent prior. Returns the flips."""
    flips = 0
    D = PREFETCH_AHEAD if _jumps(order) else 0
    c_off, m, pairs, rays = st.c_off, st.m, st.pairs, st.rays
    for i in range(order.shape[0]):
        if D:
            _prefetch_ahead(c_off, m, pairs, rays, order, i, D, prior_log_odds)
        k = order[i]
        lo = prior_log_odds[k] + _lik_ratio(st, k)
        cur = m[k]
        v = new_value(lo, uniforms[i], cur, update)
        if v != cur:
            _set_cell(st, k, v)
            flips += 1
    return flips


@nb.njit(cache=True, inline="always")
def _local_pass(st, order, lp, uniforms, update, kind):
    flips = 0
    D = PREFETCH_AHEAD if _jumps(order) else 0
    c_off, m, pairs, rays = st.c_off, st.m, st.pairs, st.rays
    for i in range(order.shape[0]):
        if D:
            _prefetch_ahead(c_off, m, pairs, rays, order, i, D, m)
        k = order[i]
        if kind == STENCIL:
            lo = stencil_cell_log_odds(lp, k, m)
        else:
            lo = tile_cell_log_odds(lp, k, m)
        lo += _lik_ratio(st, k)
        cur = m[k]
        v = new_value(lo, uniforms[i], cur, update)
        if v != cur:
            _set_cell(st, k, v)
            flips += 1
    return flips


@nb.njit(cache=True)
def sweep_local(st, order, lp, uniforms, update):
    """:func:`sweep_independent` with a correlated prior's local log-odds ``l(m_k | m_-k)`` from a
    :mod:`ogm_ppl.priors.local` bundle (one loop per prior kind, each inlining its own conditional)."""
    if lp.kind == STENCIL:
        return _local_pass(st, order, lp, uniforms, update, STENCIL)
    return _local_pass(st, order, lp, uniforms, update, TILES)


@nb.njit(cache=True)
def marginals_independent(st, order, prior_log_odds, num_sweeps, seed, update):
    """``num_sweeps`` passes over ``order`` in one compiled call with numba's generator seeded by
    ``seed``; returns the running sum of the sampled maps (``K`` float64): for long runs of small problems
    (e.g. the 10^5-sweep column of Table 3.1), where one Python call per sweep would dominate."""
    np.random.seed(seed)
    acc = np.zeros(st.m.shape[0], np.float64)
    m = st.m
    for _ in range(num_sweeps):
        for i in range(order.shape[0]):
            k = order[i]
            lo = prior_log_odds[k] + _lik_ratio(st, k)
            cur = m[k]
            v = new_value(lo, np.random.random(), cur, update)
            if v != cur:
                _set_cell(st, k, v)
        for k in range(m.shape[0]):
            acc[k] += m[k]
    return acc
