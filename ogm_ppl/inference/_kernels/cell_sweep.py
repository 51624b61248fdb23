"""Compiled single-cell sweeps over one state bundle (Sections 4.1, 4.1.2): heat-bath Gibbs and
metropolised Gibbs, with an independent or a correlated prior.

Data layout, chosen for the sweep's memory traffic (one L = 1 sweep visits every (ray, cell) pair once):

* ``pairs`` (by cell, contiguous per cell): ``(ll, ray, kappa)`` records of 16 bytes, where ``ll`` is
  ``log p(z_ray | first hit at kappa)``, so the likelihood of "this cell is the ray's first hit" streams
  in with the index instead of being looked up in the ``R x (F + 1)`` table;
* ``rays`` (by ray): ``(ll_hit, f)`` records, the ray's first occupied kappa ``f`` and
  ``ll[ray, f]``: the state a flip reads, 16 bytes a ray, so one cache line serves both.

Flipping cell ``k`` costs the rays through ``k`` not blocked before it; only when a ray's first hit is
freed is the next occupied cell searched for along the ray (the CSR ``offsets, cells``) and the table
``ll`` read. :class:`CellState` bundles the arrays so that compiled code takes one argument.

Update rules: ``HEAT_BATH`` draws ``m_k ~ p(m_k | m_-k, z)`` (Eq. 4.2, the thesis's Gibbs);
``METROPOLISED`` proposes the flip and accepts it with ``min(1, p(flip) / p(stay))`` (Liu's metropolised
Gibbs: for a binary cell it moves at least as often as heat bath, so it is no worse in Peskun's order).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba as nb
import numpy as np

from ogm_ppl.priors.local import STENCIL, TILES, stencil_cell_log_odds, tile_cell_log_odds

HEAT_BATH = 0
METROPOLISED = 1

PAIR = np.dtype([("ll", np.float64), ("ray", np.int32), ("kappa", np.int32)], align=True)
RAY = np.dtype([("ll_hit", np.float64), ("f", np.int64)], align=True)


class CellState(NamedTuple):
    """The map and the per-ray state a single-cell sweep reads and writes, with the index it walks."""

    m: np.ndarray  # K uint8: the map
    rays: np.ndarray  # R RAY records: first occupied kappa f and ll[r, f]
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


@nb.njit(cache=True, inline="always")
def _next_occupied(st, r, start):
    a = st.offsets[r]
    n = st.offsets[r + 1] - a
    for j in range(start, n):
        if st.m[st.cells[a + j]]:
            return j
    return n


@nb.njit(cache=True)
def log_lik_ratio(st, k):
    """``log p(z | m_k = 1, m_-k) - log p(z | m_k = 0, m_-k)`` (Eq. 2.4, 4.2); rays blocked before ``k``
    are skipped, and a difference of two impossible readings (``-inf - -inf``) counts as no preference."""
    d = 0.0
    pairs = st.pairs
    rays = st.rays
    for p in range(st.c_off[k], st.c_off[k + 1]):
        kap = pairs[p].kappa
        r = pairs[p].ray
        fr = rays[r].f
        if fr < kap:
            continue
        if fr > kap:
            t = pairs[p].ll - rays[r].ll_hit
        else:  # k is the ray's first hit: without it the ray runs on to the next occupied cell
            t = pairs[p].ll - st.ll[r, _next_occupied(st, r, kap + 1)]
        if t == t:
            d += t
    return d


@nb.njit(cache=True)
def set_cell(st, k, v):
    """``m[k] = v``, keeping every ray's first hit (and its likelihood) in step."""
    if st.m[k] == v:
        return
    st.m[k] = v
    pairs = st.pairs
    rays = st.rays
    for p in range(st.c_off[k], st.c_off[k + 1]):
        kap = pairs[p].kappa
        r = pairs[p].ray
        if v:
            if kap < rays[r].f:
                rays[r].f = kap
                rays[r].ll_hit = pairs[p].ll
        elif rays[r].f == kap:
            n = _next_occupied(st, r, kap + 1)
            rays[r].f = n
            rays[r].ll_hit = st.ll[r, n]


@nb.njit(cache=True, inline="always")
def new_value(lo, u, cur, update):
    """The cell's next value given its conditional log-odds ``lo`` and a uniform ``u``.

    Heat bath: occupied with probability ``sigmoid(lo)``. Metropolised: flip with probability
    ``min(1, exp(+-lo))`` (``+lo`` from free, ``-lo`` from occupied). ``nan`` (both values without prior
    mass, so the state has none) moves by a fair coin so that the chain can leave such a state.
    """
    if lo != lo:
        return 1 if u < 0.5 else 0
    if update == METROPOLISED:
        d = -lo if cur else lo  # log p(flip) - log p(stay)
        if d >= 0.0 or (d > -np.inf and u < math.exp(d)):
            return 1 - cur
        return cur
    if lo >= 0.0:
        return 1 if u * (1.0 + math.exp(-lo)) < 1.0 else 0
    e = math.exp(lo)
    return 1 if u * (1.0 + e) < e else 0


@nb.njit(cache=True)
def sweep_independent(st, order, prior_log_odds, uniforms, update):
    """One pass of single-cell updates over ``order`` with an independent prior. Returns the flips."""
    flips = 0
    for i in range(order.shape[0]):
        k = order[i]
        lo = prior_log_odds[k] + log_lik_ratio(st, k)
        v = new_value(lo, uniforms[i], st.m[k], update)
        if v != st.m[k]:
            set_cell(st, k, v)
            flips += 1
    return flips


@nb.njit(cache=True, inline="always")
def _local_pass(st, order, lp, uniforms, update, kind):
    flips = 0
    for i in range(order.shape[0]):
        k = order[i]
        if kind == STENCIL:
            lo = stencil_cell_log_odds(lp, k, st.m)
        else:
            lo = tile_cell_log_odds(lp, k, st.m)
        lo += log_lik_ratio(st, k)
        v = new_value(lo, uniforms[i], st.m[k], update)
        if v != st.m[k]:
            set_cell(st, k, v)
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
    for _ in range(num_sweeps):
        for i in range(order.shape[0]):
            k = order[i]
            lo = prior_log_odds[k] + log_lik_ratio(st, k)
            v = new_value(lo, np.random.random(), st.m[k], update)
            if v != st.m[k]:
                set_cell(st, k, v)
        for k in range(st.m.shape[0]):
            acc[k] += st.m[k]
    return acc
