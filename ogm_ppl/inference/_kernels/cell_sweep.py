"""Compiled single-cell sweeps (Sections 4.1, 4.1.2): heat-bath Gibbs and metropolised Gibbs, with an
independent or a correlated prior, over one state bundle that keeps every cell's likelihood ratio.

**What is kept.** The single-cell update needs (Eq. 2.4, 4.2)

    d_k = log p(z | m_k = 1, m_-k) - log p(z | m_k = 0, m_-k) = sum_r c_r(kappa_r(k)),

a sum over the rays ``r`` through cell ``k`` (at position ``kappa``) of the ray's term, which depends on the
ray's first and second occupied positions ``f_r < s_r`` (``len(r)`` where there is none), not on ``m_k``:

    c_r(kappa) = ll[r, kappa] - ll[r, f_r]   for kappa < f_r    (the ray reaches k: k occupied would end it)
    c_r(f_r)   = ll[r, f_r]   - ll[r, s_r]                       (k is its first hit: freed, it runs on to s_r)
    c_r(kappa) = 0                            for kappa > f_r    (blocked before k: Section 4.1.2)

with ``ll[r, kappa] = log p(z_r | first hit at kappa)`` (column ``len(r)``: no hit). Rather than summing the
rays through ``k`` at every visit (about 25 (ray, cell) pairs a cell, 6.3 M a sweep of the 500 x 500
reference scene), the state holds ``d_k`` for every cell and updates it only when a ray's ``f`` or ``s``
changes, i.e. when a cell flips: a visit reads the cell's kept sum (and its counts of infinite terms), and a
flip walks the rays whose first or second hit it moves (:func:`_retarget`). Once a chain has burnt in, few
cells flip (about 2 % a sweep in the reference scene), so a sweep costs a fraction of the pair sum, and a
visit in a scan that jumps about the map misses the cache a few times instead of once for every ray
(``benchmarks/sweep_before_after.py`` measures both).

**Exact arithmetic.** An updated floating-point sum would drift from the sum it stands for and depend on
the order of the updates. ``d_k`` is therefore held in fixed point: every finite table entry counts as
``q(x) = rint(x * 2^S)`` (an int64) and ``d_k`` is the integer sum of ``q(ll[r, kappa]) - q(ll[r, g])``, so
every update is exact and the kept value always *equals* the sum from scratch, whatever happened before
(``tests/inference/mcmc/test_cell_sweep_layout.py`` checks it after every flip). ``S`` is chosen per model
(:func:`fixed_point_bits`) so that no cell's sum can leave the int64 range; the conditional log-odds differ
from the floating-point sum of the table by at most ``n_k 2^-S`` (``n_k``: rays through ``k``; ``S = 43``
in the 500 x 500 reference scene, where a cell has up to 778 rays: a bound of 9e-11). Impossible readings (``-inf``
entries) are counted
apart: a term ``x - (-inf)`` adds to ``pos_k``, ``-inf - y`` to ``neg_k``, and ``-inf - -inf`` counts as no
preference; ``d_k`` is then ``+inf`` (``pos_k > 0``), ``-inf`` (``neg_k > 0``) or ``nan`` (both: the state
has no mass either way and the cell moves by a fair coin, see :func:`new_value`).

Update rules: ``HEAT_BATH`` draws ``m_k ~ p(m_k | m_-k, z)`` (Eq. 4.2, the thesis's Gibbs);
``METROPOLISED`` proposes the flip and accepts it with ``min(1, p(flip) / p(stay))`` (Liu's metropolised
Gibbs: for a binary cell it moves at least as often as heat bath, so it is no worse in Peskun's order).
:class:`CellState` bundles the arrays so that compiled code takes one argument.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba as nb
import numpy as np

from ogm_ppl._numba_cache import njit_shipped
from ogm_ppl.inference._kernels.cells import _next_occupied
from ogm_ppl.priors.compiled import cell_log_odds

HEAT_BATH = 0
METROPOLISED = 1
#: scan codes of :func:`draws`
SYSTEMATIC, PERMUTATION, RANDOM = 0, 1, 2

#: the counts of a cell's infinite terms (``x - (-inf)``, ``-inf - y``)
INF = np.dtype([("pos", np.int32), ("neg", np.int32)], align=True)
#: a ray's first and second occupied positions (``len(ray)`` where there is none)
RAY = np.dtype([("f", np.int64), ("s", np.int64)], align=True)
#: the fewest fraction bits :func:`fixed_point_bits` accepts (a resolution of 1e-6 in a log-likelihood)
MIN_BITS = 20
# Far from 0, a cell's log-odds decide its update without exp(), bit for bit: for lo > _FAR,
# 1 + exp(-lo) rounds to 1; for lo < -_FAR, exp(lo) <= exp(-40) = 4.25e-18 < _TINY_U, so a uniform
# u >= _TINY_U rejects whatever exp() returns (the same holds for a metropolised flip's log-ratio).
_FAR = 40.0
_TINY_U = 4.3e-18


class CellState(NamedTuple):
    """The map, the per-ray first / second hits and the per-cell likelihood ratios a sweep reads and
    writes, with the indexes it walks."""

    m: np.ndarray  # K uint8: the map
    rays: np.ndarray  # R RAY records: first and second occupied kappa
    d: np.ndarray  # K int64: the fixed-point sum of each cell's finite terms
    inf: np.ndarray  # K INF records: the counts of each cell's infinite terms (kept only if any_inf)
    any_inf: bool  # whether an entry a ray uses is -inf (if not, no term is infinite: the counts stay 0)
    offsets: np.ndarray  # R + 1 int64: CSR along rays
    cells: np.ndarray  # nnz int64: cells of each ray in kappa order
    c_off: np.ndarray  # K + 1 int64: CSR by cell
    c_ray: np.ndarray  # nnz int64: the rays through each cell
    c_kappa: np.ndarray  # nnz int64: the cell's position on each of them
    ll: np.ndarray  # R x (F + 1) float64: log p(z_r | first hit at kappa); column len(r) = no hit
    scale: float  # 2^S: a finite entry x counts as rint(x * scale)


def fixed_point_bits(ll: np.ndarray, c_off: np.ndarray) -> int:
    """The fraction bits ``S`` of the fixed-point likelihood ratios: the most (at most 60) such that no
    cell's sum of terms ``|q(x) - q(y)| <= 2 max|ll| 2^S + 1`` over its ``n_k`` rays can exceed ``2^62``.
    Raises ``ValueError`` on ``+inf`` / ``nan`` entries, or when fewer than :data:`MIN_BITS` bits remain."""
    bad = np.isnan(ll) | (ll == np.inf)
    if bad.any():
        r, j = np.argwhere(bad)[0]
        raise ValueError(
            f"the likelihood table holds {ll[r, j]} at ray {r}, kappa {j}: log-likelihoods must be "
            "finite or -inf (an impossible reading)"
        )
    finite = ll[np.isfinite(ll)]
    big = float(np.abs(finite).max()) if finite.size else 0.0
    n = int(np.diff(c_off).max()) if len(c_off) > 1 else 0
    bound = n * (2.0 * big + 1.0) + 1.0  # in units of 2^S
    bits = min(60, math.floor(62 - math.log2(bound)))
    if bits < MIN_BITS:
        raise ValueError(
            f"likelihood entries up to |{big:.3g}| over up to {n} rays a cell leave {bits} fraction "
            f"bits for the fixed-point sums (need {MIN_BITS})"
        )
    return bits


def cell_state(
    m: np.ndarray, offsets, cells, c_off, c_ray, c_kappa, ll: np.ndarray, bits: int | None = None
) -> CellState:
    """The state of map ``m`` (uint8, ``K``): every ray's first and second hits and every cell's ``d_k``,
    computed from scratch (one pass over the rays)."""
    bits = fixed_point_bits(ll, c_off) if bits is None else bits
    st = CellState(
        np.ascontiguousarray(m, dtype=np.uint8),
        np.empty(len(offsets) - 1, RAY),
        np.zeros(len(m), np.int64),
        np.zeros(len(m), INF),
        _any_impossible(ll, offsets),
        offsets,
        cells,
        c_off,
        c_ray,
        c_kappa,
        ll,
        float(2.0**bits),
    )
    _fill(st)
    return st


def cell_state_of(m: np.ndarray, index, bits: int | None = None) -> CellState:
    """:func:`cell_state` over a :class:`~ogm_ppl.raycast.RayIndex`."""
    return cell_state(m, index.offsets, index.cells, index.c_off, index.c_ray, index.c_kappa, index.ll, bits)


@nb.njit(cache=True)
def _any_impossible(ll, offsets):
    """Whether an entry a ray can use (``kappa <= len(ray)``; the rest of the row is ``-inf`` padding) is ``-inf``."""
    for r in range(offsets.shape[0] - 1):
        for j in range(offsets[r + 1] - offsets[r] + 1):
            if ll[r, j] == -np.inf:
                return True
    return False


@nb.njit(cache=True)
def _fill(st):
    for r in range(st.rays.shape[0]):
        n = st.offsets[r + 1] - st.offsets[r]
        f = _next_occupied(st.m, st.offsets, st.cells, r, 0)
        s = _next_occupied(st.m, st.offsets, st.cells, r, f + 1) if f < n else n
        st.rays[r].f = f
        st.rays[r].s = s
        for kap in range(min(f, n - 1) + 1):
            _ray_term(st, r, kap, f, s, 1)


@nb.njit(cache=True, inline="always")
def _q(x, scale):
    return np.int64(np.rint(x * scale))


@nb.njit(cache=True, inline="always")
def _add_term(st, c, r, x, y, sign):
    """``d_c += sign * (ll[r, x] - ll[r, y])`` in fixed point (or the count of an infinite term)."""
    a = st.ll[r, x]
    b = st.ll[r, y]
    if not st.any_inf:
        st.d[c] += sign * (_q(a, st.scale) - _q(b, st.scale))
    elif a > -np.inf:
        if b > -np.inf:
            st.d[c] += sign * (_q(a, st.scale) - _q(b, st.scale))
        else:
            st.inf[c].pos += sign
    elif b > -np.inf:
        st.inf[c].neg += sign


@nb.njit(cache=True, inline="always")
def _ray_term(st, r, kap, f, s, sign):
    """Add ``sign * c_r(kap)`` for a ray whose first and second hits are ``f``, ``s`` (module docstring)."""
    c = st.cells[st.offsets[r] + kap]
    if kap < f:
        _add_term(st, c, r, kap, f, sign)
    elif kap == f:
        _add_term(st, c, r, f, s, sign)


@nb.njit(cache=True, inline="always")
def _retarget(st, r, f1, s1):
    """Move ray ``r``'s first / second hits to ``f1``, ``s1``, updating the kept terms of the cells it reaches."""
    f0 = st.rays[r].f
    s0 = st.rays[r].s
    st.rays[r].f = f1
    st.rays[r].s = s1
    a = st.offsets[r]
    n = st.offsets[r + 1] - a
    if f0 == f1:  # only the first hit's own term changes: ll[f] - ll[s0] -> ll[f] - ll[s1]
        if s0 != s1 and f0 < n:
            c = st.cells[a + f0]
            _add_term(st, c, r, f0, s1, 1)
            _add_term(st, c, r, f0, s0, -1)
        return
    lo = min(f0, f1)
    b0 = st.ll[r, f0]
    b1 = st.ll[r, f1]
    if not st.any_inf:  # before both hits each term changes by q(b0) - q(b1)
        delta = _q(b0, st.scale) - _q(b1, st.scale)
        for kap in range(lo):
            st.d[st.cells[a + kap]] += delta
    elif b0 > -np.inf and b1 > -np.inf:  # so does each finite one
        delta = _q(b0, st.scale) - _q(b1, st.scale)
        for kap in range(lo):
            if st.ll[r, kap] > -np.inf:
                st.d[st.cells[a + kap]] += delta
    else:
        for kap in range(lo):
            c = st.cells[a + kap]
            _add_term(st, c, r, kap, f1, 1)
            _add_term(st, c, r, kap, f0, -1)
    for kap in range(lo, min(max(f0, f1), n - 1) + 1):
        _ray_term(st, r, kap, f1, s1, 1)
        _ray_term(st, r, kap, f0, s0, -1)


@nb.njit(cache=True)
def log_lik_ratio(st, k):
    """``log p(z | m_k = 1, m_-k) - log p(z | m_k = 0, m_-k)`` (Eq. 2.4, 4.2), from the kept sum: rays
    blocked before ``k`` add nothing, and a difference of two impossible readings (``-inf - -inf``)
    counts as no preference."""
    return _lik_ratio(st, k)


@nb.njit(cache=True, inline="always")
def _lik_ratio(st, k):
    if st.any_inf:
        rec = st.inf[k]
        if rec.pos > 0:
            return np.nan if rec.neg > 0 else np.inf
        if rec.neg > 0:
            return -np.inf
    return st.d[k] / st.scale


@nb.njit(cache=True)
def set_cell(st, k, v):
    """``m[k] = v``, keeping every ray's first and second hits and every cell's likelihood ratio in step."""
    if st.m[k] == v:
        return
    _set_cell(st, k, v)


# compiled once per state type and called (not inlined): it runs only when a cell flips, and inlining its
# ``_retarget`` / ``_ray_term`` / ``_add_term`` tree into each kernel and prior kind cost most of their compile time
@nb.njit(cache=True)
def _set_cell(st, k, v):
    st.m[k] = v
    for p in range(st.c_off[k], st.c_off[k + 1]):
        r = st.c_ray[p]
        kap = st.c_kappa[p]
        f = st.rays[r].f
        s = st.rays[r].s
        if v:
            if kap < f:  # the new first hit: the old one is now the second
                _retarget(st, r, kap, f)
            elif kap < s:  # the new second hit
                _retarget(st, r, f, kap)
        elif kap == f:  # the first hit freed: the second takes over, the next occupied after it is second
            n = st.offsets[r + 1] - st.offsets[r]
            _retarget(st, r, s, _next_occupied(st.m, st.offsets, st.cells, r, s + 1) if s < n else n)
        elif kap == s:  # the second hit freed
            _retarget(st, r, f, _next_occupied(st.m, st.offsets, st.cells, r, kap + 1))


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


_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_M1 = np.uint64(0xBF58476D1CE4E5B9)
_M2 = np.uint64(0x94D049BB133111EB)


@nb.njit(cache=True, inline="always")
def _splitmix64(x):
    """SplitMix64's output function (Steele, Lea & Flood 2014; Java's ``SplittableRandom``): the ``i``-th
    number of the stream seeded by ``s`` is ``_splitmix64(s + (i + 1) * golden)``; it passes BigCrush."""
    z = x
    z = (z ^ (z >> np.uint64(30))) * _M1
    z = (z ^ (z >> np.uint64(27))) * _M2
    return z ^ (z >> np.uint64(31))


@nb.njit(cache=True, inline="always")
def _uniform(seed, i):
    """The ``i``-th uniform on [0, 1) of the stream ``seed``: 53 random bits."""
    return np.float64(_splitmix64(seed + np.uint64(i + 1) * _GOLDEN) >> np.uint64(11)) * (1.0 / 9007199254740992.0)


@nb.njit(cache=True)
def draws(cells, scan, seed):
    """One sweep's visiting order over ``cells`` and its uniforms (``float64``), from the SplitMix64 stream
    ``seed`` (a uint64): ``SYSTEMATIC`` (``cells`` as given), ``PERMUTATION`` (a Fisher-Yates shuffle) or
    ``RANDOM`` (drawn with replacement: ``floor(u n)``, biased by at most ``n 2^-53``). About 1 ms for
    250,000 cells, where torch's generator and indexing took 3-7 ms and numba's Mersenne twister 2.6-7."""
    n = cells.shape[0]
    u = np.empty(n, np.float64)
    for i in range(n):
        u[i] = _uniform(seed, i)
    if scan == PERMUTATION:
        order = cells.copy()
        for i in range(n - 1, 0, -1):  # Fisher-Yates with the stream's numbers n .. 2n - 2
            j = min(np.int64(_uniform(seed, n + i) * (i + 1)), i)
            t = order[i]
            order[i] = order[j]
            order[j] = t
    elif scan == RANDOM:
        order = np.empty(n, cells.dtype)
        for i in range(n):
            order[i] = cells[min(np.int64(_uniform(seed, n + i) * n), n - 1)]
    else:
        order = cells
    return order, u


# The pure loops below compile without numba's runtime (``_nrt=False``): with it, every inlined call that
# takes a bundle (the prior's conditional, the kept sums) counts the references of each of its arrays, an
# atomic add and subtract per array per cell that numba's pruning leaves in these branching loops, and
# that cost more than a pattern field's conditional itself. They allocate nothing, so they need no runtime
# (``benchmarks/bench_priors.py --overhead`` times them).
@njit_shipped(_nrt=False)
def sweep(st, order, prior, uniforms, update):
    """One pass of single-cell updates over ``order`` with the prior bundle ``prior``
    (:mod:`ogm_ppl.priors.compiled`; numba compiles one loop per bundle type, inlining its conditional
    ``l(m_k | m_-k)``). Returns the flips."""
    flips = 0
    m = st.m
    for i in range(order.shape[0]):
        k = order[i]
        lo = cell_log_odds(prior, k, m)
        lo += _lik_ratio(st, k)
        cur = m[k]
        v = new_value(lo, uniforms[i], cur, update)
        if v != cur:
            _set_cell(st, k, v)
            flips += 1
    return flips


@njit_shipped
def prior_log_odds(prior, k, m):
    """``l(m_k | m_-k)`` of the prior bundle at the map ``m`` (callable from Python)."""
    return cell_log_odds(prior, k, m)


@njit_shipped(_nrt=False)
def icm_sweeps(st, order, prior, max_sweeps):
    """Iterated conditional modes (the EM hill-climbing of Section 2.2) over ``order``: each cell takes
    the value with the larger conditional posterior (ties, and ``nan``, keep the current value), until a
    sweep changes nothing. Returns the number of sweeps run."""
    m = st.m
    for s in range(max_sweeps):
        changed = 0
        for i in range(order.shape[0]):
            k = order[i]
            lo = cell_log_odds(prior, k, m)
            lo += _lik_ratio(st, k)
            v = m[k]
            if lo > 0.0:
                v = 1
            elif lo < 0.0:
                v = 0
            if v != m[k]:
                _set_cell(st, k, v)
                changed += 1
        if changed == 0:
            return s + 1
    return max_sweeps


@njit_shipped
def marginals(st, order, prior, num_sweeps, seed, update):
    """``num_sweeps`` passes over ``order`` in one compiled call with numba's generator seeded by
    ``seed``; returns the running sum of the sampled maps (``K`` float64): for long runs of small problems
    (e.g. the 10^5-sweep column of Table 3.1), where one Python call per sweep would dominate."""
    np.random.seed(seed)
    acc = np.zeros(st.m.shape[0], np.float64)
    _marginal_passes(st, order, prior, num_sweeps, update, acc)
    return acc


@njit_shipped(_nrt=False)
def _marginal_passes(st, order, prior, num_sweeps, update, acc):
    """The passes of :func:`marginals`, adding each sampled map into ``acc`` (without numba's runtime)."""
    m = st.m
    for _ in range(num_sweeps):
        for i in range(order.shape[0]):
            k = order[i]
            lo = cell_log_odds(prior, k, m)
            lo += _lik_ratio(st, k)
            cur = m[k]
            v = new_value(lo, np.random.random(), cur, update)
            if v != cur:
                _set_cell(st, k, v)
        for k in range(m.shape[0]):
            acc[k] += m[k]
