r"""Chromatic tile sweeps: single-cell Gibbs updates of many tiles of the grid at once, exactly (Section 4.1).

**Factors and their extent.** The posterior ``p(m | z) ∝ p~(m) prod_r p(z_r | m)`` is a product of
factors, each a function of a set ``F`` of cells: a ray's likelihood reads the cells of the ray (its first
hit), and a prior's factors read a window (a stencil's pair ``{k, k + d}``, a pattern field's ``w x w``
window, ``2w x 2w`` cells at the pooled scale, a table prior's tile with its border). The *extent* of ``F``
is the largest coordinate difference of two of its cells along either axis,
``e(F) = max(max_F row - min_F row, max_F col - min_F col)`` (:func:`ray_extents`, :func:`prior_extent`).

**Tiles and colours.** The grid is cut into ``T x T`` tiles, tile ``(a, b)`` holding rows ``[aT, aT + T)``
and columns ``[bT, bT + T)`` (a 1D grid: one row of tiles), of colour ``2 (a mod 2) + (b mod 2)``, four
colours in a 2 x 2 checkerboard. A factor is *confined* when it holds cells of at most one tile of each
colour; a cell is *short* when every ray through it is confined, else *long*. ``T`` must be at least the
prior's extent.

**The rule.** *A factor ``F`` with ``e(F) <= T`` is confined.* Proof: let cells ``x in (a, b)`` and
``y in (a', b')`` of ``F`` lie in distinct tiles of one colour. Then ``a = a' (mod 2)`` and
``b = b' (mod 2)``, and the tiles differ, so ``|a - a'| >= 2`` or ``|b - b'| >= 2``; say ``a' >= a + 2``.
Then ``row(y) >= a'T >= (a + 2) T`` and ``row(x) <= aT + T - 1``, so ``row(y) - row(x) >= T + 1 > e(F)``:
a contradiction. So every prior window is confined, and so is every ray of extent ``<= T`` (a longer ray
may be too, if it crosses only tiles of distinct colours; :func:`tile_layout` checks each ray).

**Why a phase is exact.** Two short cells ``k, k'`` in distinct tiles of one colour share no factor: a ray
through both would not be confined (and ``k`` would be long), a prior window through both would have
extent ``> T``. So ``k'`` lies outside the Markov blanket of ``k``, and the conditional
``p(m_k | m_-k, z)`` that an update of ``k`` draws from does not depend on any cell that the other tiles
of the colour update. Updating the short cells of all tiles of one colour at once (each tile by its own
sequential scan) therefore gives exactly the map that updating the tiles one after another gives, in any
order of the tiles: a *colour phase* is a composition of single-cell Gibbs updates, each ``pi``-invariant,
so the sweep (the four colour phases, then the long cells one after another) leaves the posterior
invariant. Every visited cell is updated once per sweep (systematic / permutation scans) or, for the
random scan, each tile and the long cells draw as many updates (with replacement) as they hold cells.

**The kept sums under threads.** The single-cell state
(:mod:`~ogm_ppl.inference._kernels.cell_sweep`) keeps, per cell, the fixed-point sum ``d_k`` of its rays'
terms, and a flip of ``k`` rewrites it along the rays through ``k`` (their first / second hits move).
Those rays are confined, so every cell they write lies in ``k``'s tile or in a tile of *another* colour;
their ``f, s`` records are touched by ``k``'s tile alone, and so is every ``m`` entry and every kept sum
of the tiles of the phase's colour (the only ones read during the phase). But two tiles of one colour may
write the sum of one cell of another colour through different rays: a data race. Writes into a cell of
the updating tile are plain; writes into any other cell are ``lock add`` instructions (:func:`atomic_add`,
LLVM ``atomicrmw add``). Integer addition is exact, associative and commutative, so after the phase every
sum equals the sum from scratch, whatever the interleaving (the kept counts of infinite terms likewise,
as int32 atomics). No buffer is needed: the extra memory of the threaded sweep is the tile index and each
ray's runs of cells in one tile (:func:`ray_runs`, which spare the writes along a ray an ownership test a
cell).

**Random numbers.** The sweep seed ``s`` (a uint64) gives tile ``t`` the SplitMix64 stream
``tile_seed(s, t)`` (its order and uniforms by :func:`~ogm_ppl.inference._kernels.cell_sweep.draws`), and the
long cells the stream of ``t = n_tiles``. Since a phase's result does not depend on the order or the
interleaving of its tiles, the chain is a function of its seed alone: the same for 1, 2 or 64 threads.
"""

from __future__ import annotations

from typing import NamedTuple

import numba as nb
import numpy as np
from numba.core import cgutils, types
from numba.extending import intrinsic

from ogm_ppl._numba_cache import njit_shipped
from ogm_ppl.inference._kernels import cell_sweep as cs
from ogm_ppl.inference._kernels.cells import _next_occupied
from ogm_ppl.priors.compiled import cell_log_odds

__all__ = [
    "COLOURS",
    "TileLayout",
    "atomic_add",
    "fetch_add",
    "chromatic_sweep",
    "colour_of_tile",
    "confined_rays",
    "prior_extent",
    "ray_extents",
    "tile_layout",
    "tile_pass",
    "tile_seed",
]

#: colour phases of a sweep (the 2 x 2 checkerboard)
COLOURS = 4


def _int_array(arr) -> bool:
    return isinstance(arr, types.Array) and arr.ndim == 1 and isinstance(arr.dtype, types.Integer)


def _rmw_add(context, builder, signature, args):
    """``atomicrmw add`` (monotonic) on ``args[0][args[1]]``; returns the old value."""
    aryty = signature.args[0]
    ary = context.make_array(aryty)(context, builder, args[0])
    ptr = cgutils.get_item_pointer(context, builder, aryty, ary, [args[1]])
    return builder.atomic_rmw("add", ptr, args[2], "monotonic")


@intrinsic
def atomic_add(typingctx, arr, i, v):
    """``arr[i] += v`` as one atomic read-modify-write (LLVM ``atomicrmw add``, monotonic ordering) on a
    1D C-contiguous integer array: concurrent adds to one entry from several threads are all kept."""
    if not _int_array(arr):
        return None

    def codegen(context, builder, signature, args):
        _rmw_add(context, builder, signature, args)
        return context.get_dummy_value()

    return types.void(arr, types.intp, arr.dtype), codegen


@intrinsic
def fetch_add(typingctx, arr, i, v):
    """``old = arr[i]; arr[i] += v; return old`` as one atomic read-modify-write (LLVM ``atomicrmw add``,
    monotonic) on a 1D C-contiguous integer array: a shared counter from which threads take work."""
    if not _int_array(arr):
        return None
    return arr.dtype(arr, types.intp, arr.dtype), _rmw_add


class TileLayout(NamedTuple):
    """The tiles of a chromatic sweep: ``T x T`` tiles on a ``rows x cols`` grid (``n_tr x n_tc`` of them,
    tile ``t = a n_tc + b``), the short cells to visit grouped by tile (CSR ``tile_off`` / ``tile_cells``,
    row-major within a tile), the non-empty tiles of each colour (CSR ``col_off`` / ``col_tiles``, the
    tiles with more ray entries first), the long cells (on a ray that is not confined), visited last, and
    each ray's runs of cells in one tile (CSR ``seg_off`` over the rays / ``seg_start``, the first ray
    position of each run, ``seg_tile``, its tile), so that a flip's writes along a ray test ownership once
    a run, not once a cell."""

    rows: int
    cols: int
    T: int
    n_tr: int
    n_tc: int
    tile_off: np.ndarray  # n_tiles + 1 int64
    tile_cells: np.ndarray  # short visited cells, int64
    col_off: np.ndarray  # COLOURS + 1 int64
    col_tiles: np.ndarray  # non-empty tiles, int64
    long_cells: np.ndarray  # int64
    seg_off: np.ndarray  # n_rays + 1 int64
    seg_start: np.ndarray  # int64
    seg_tile: np.ndarray  # int64

    @property
    def n_tiles(self) -> int:
        return self.n_tr * self.n_tc


@nb.njit(cache=True)
def ray_extents(offsets, cells, cols):
    """``e(r)`` of every ray (``R`` int64): the larger of its row and column spans (cells ``c``,
    ``row = c // cols``); 0 for a ray without cells."""
    R = offsets.shape[0] - 1
    out = np.zeros(R, np.int64)
    for r in range(R):
        a, b = offsets[r], offsets[r + 1]
        if a == b:
            continue
        r0 = r1 = cells[a] // cols
        c0 = c1 = cells[a] - r0 * cols
        for j in range(a + 1, b):
            y = cells[j] // cols
            x = cells[j] - y * cols
            r0, r1, c0, c1 = min(r0, y), max(r1, y), min(c0, x), max(c1, x)
        out[r] = max(r1 - r0, c1 - c0)
    return out


def prior_extent(prior) -> int:
    """The largest extent of a factor of the compiled prior ``prior`` (module docstring): what its bundle's
    ``factor_extent()`` says (0 for independent cells, ``max(|dr|, |dc|)`` over a stencil's offsets, ``w - 1``
    for a pattern field, ``2w - 1`` with the pooled scale, the window's span for a table prior's tiles)."""
    extent = getattr(prior, "factor_extent", None)
    if extent is None:
        raise TypeError(f"a compiled prior of type {type(prior).__name__} does not say its factor_extent()")
    return int(extent())


def colour_of_tile(t: int | np.ndarray, n_tc: int):
    """The colour ``2 (a mod 2) + (b mod 2)`` of tile ``t = a n_tc + b``."""
    return 2 * ((t // n_tc) % 2) + (t % n_tc) % 2


@nb.njit(cache=True)
def confined_rays(offsets, cells, cols, T, n_tc, o_r=0, o_c=0):
    """Whether each ray is confined (``R`` bool): its cells lie in at most one ``T x T`` tile of each colour
    (tiles ``n_tc`` to a row of tiles, tile ``(0, 0)`` starting at row ``o_r``, column ``o_c``, both ``<= 0``)."""
    R = offsets.shape[0] - 1
    out = np.ones(R, np.bool_)
    seen = np.empty(COLOURS, np.int64)
    for r in range(R):
        seen[:] = -1
        for j in range(offsets[r], offsets[r + 1]):
            y = cells[j] // cols
            x = cells[j] - y * cols
            a, b = (y - o_r) // T, (x - o_c) // T
            t = a * n_tc + b
            col = 2 * (a % 2) + b % 2
            if seen[col] < 0:
                seen[col] = t
            elif seen[col] != t:
                out[r] = False
                break
    return out


@nb.njit(cache=True)
def _long_mask(K, offsets, cells, confined):
    long = np.zeros(K, np.bool_)
    for r in range(offsets.shape[0] - 1):
        if not confined[r]:
            for j in range(offsets[r], offsets[r + 1]):
                long[cells[j]] = True
    return long


@nb.njit(cache=True)
def _ray_runs_pass(offsets, cells, cols, T, n_tc, seg_off, seg_start, seg_tile):
    """One pass of :func:`ray_runs`: the runs counted into ``seg_off``, and written where ``seg_start`` has
    room for them (empty: count only)."""
    write = seg_start.shape[0] > 0
    n = 0
    for r in range(offsets.shape[0] - 1):
        prev = -1
        for j in range(offsets[r], offsets[r + 1]):
            c = cells[j]
            t = (c // cols // T) * n_tc + (c % cols) // T
            if t != prev:
                if write:
                    seg_start[n] = j - offsets[r]
                    seg_tile[n] = t
                n += 1
                prev = t
        seg_off[r + 1] = n


def ray_runs(offsets, cells, cols: int, T: int, n_tc: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each ray's maximal runs of consecutive cells in one ``T x T`` tile: CSR ``seg_off`` (per ray) over
    ``seg_start`` (a run's first position along its ray) and ``seg_tile`` (its tile ``a n_tc + b``), int64."""
    seg_off = np.zeros(len(offsets), np.int64)
    none = np.zeros(0, np.int64)
    _ray_runs_pass(offsets, cells, cols, T, n_tc, seg_off, none, none)
    seg_start = np.empty(seg_off[-1], np.int64)
    seg_tile = np.empty(seg_off[-1], np.int64)
    if len(seg_start):
        _ray_runs_pass(offsets, cells, cols, T, n_tc, seg_off, seg_start, seg_tile)
    return seg_off, seg_start, seg_tile


@nb.njit(cache=True)
def _is_sorted(a):
    for i in range(1, a.shape[0]):
        if a[i - 1] > a[i]:
            return False
    return True


@nb.njit(cache=True)
def _fill_tiles(visit, long, c_off, cols, T, n_tc, n_tiles):
    """The short cells of the sorted ``visit`` grouped by tile (row-major within a tile, as ``visit``):
    CSR ``tile_off`` / ``tile_cells``, and each tile's cost (its cells' ray entries plus one each), in two
    passes and without a temporary per cell."""
    count = np.zeros(n_tiles, np.int64)
    cost = np.zeros(n_tiles, np.float64)
    for k in visit:
        if not long[k]:
            t = (k // cols // T) * n_tc + (k % cols) // T
            count[t] += 1
            cost[t] += c_off[k + 1] - c_off[k] + 1.0
    tile_off = np.zeros(n_tiles + 1, np.int64)
    for t in range(n_tiles):
        tile_off[t + 1] = tile_off[t] + count[t]
    tile_cells = np.empty(tile_off[n_tiles], np.int64)
    for t in range(n_tiles):
        count[t] = tile_off[t]  # the next free slot of tile t
    for k in visit:
        if not long[k]:
            t = (k // cols // T) * n_tc + (k % cols) // T
            tile_cells[count[t]] = k
            count[t] += 1
    return tile_off, tile_cells, cost


def tile_layout(visit: np.ndarray, offsets, cells, c_off, rows: int, cols: int, T: int) -> TileLayout:
    """The :class:`TileLayout` of the cells ``visit`` (int64, any order) on ``T x T`` tiles: cells on a
    ray that is not confined (:func:`confined_rays`) are long; the rest go to their tile in row-major order."""
    if T < 1:
        raise ValueError(f"the tile side must be at least 1 cell, got {T}")
    K = rows * cols
    visit = np.ascontiguousarray(visit, np.int64)
    if not _is_sorted(visit):
        visit = np.sort(visit)
    n_tr, n_tc = -(-rows // T), -(-cols // T)
    long = _long_mask(K, offsets, cells, confined_rays(offsets, cells, cols, T, n_tc))
    # a tile's cost ~ its ray entries: dealt out largest first, so that threads share a phase evenly
    tile_off, tile_cells, cost = _fill_tiles(visit, long, np.asarray(c_off, np.int64), cols, T, n_tc, n_tr * n_tc)
    ids = np.nonzero(np.diff(tile_off))[0]
    colour = colour_of_tile(ids, n_tc)
    key = np.lexsort((-cost[ids], colour))
    col_tiles = np.ascontiguousarray(ids[key].astype(np.int64))
    col_off = np.concatenate([[0], np.cumsum(np.bincount(colour, minlength=COLOURS))]).astype(np.int64)
    return TileLayout(
        int(rows),
        int(cols),
        int(T),
        int(n_tr),
        int(n_tc),
        tile_off,
        tile_cells,
        col_off,
        col_tiles,
        np.ascontiguousarray(visit[long[visit]]),
        *ray_runs(offsets, cells, cols, T, n_tc),
    )


@nb.njit(cache=True, inline="always")
def tile_seed(seed, t):
    """The SplitMix64 seed of tile ``t``'s stream in the sweep of seed ``seed`` (uint64)."""
    return cs._splitmix64(seed + np.uint64(t + 1) * cs._GOLDEN)


# ----------------------------------------------------------------- the threaded single-cell update
# Copies of cell_sweep's _add_term / _retarget / _set_cell whose writes into cells outside the updating tile
# (rows [r0, r0 + T), columns [c0, c0 + T)) are atomic adds; bit for bit the same sums.


@nb.njit(cache=True, inline="always")
def _own(c, cols, r0, c0, T, inv_cols):
    """Whether cell ``c`` lies in the tile at ``(r0, c0)``; its row by a multiplication with ``1 / cols``
    (corrected to the exact quotient) instead of a 64-bit division, which costs tens of cycles a write."""
    y = np.int64(c * inv_cols)
    if y * cols > c:
        y -= 1
    x = c - y * cols
    if x >= cols:
        y += 1
        x -= cols
    return r0 <= y < r0 + T and c0 <= x < c0 + T


@nb.njit(cache=True, inline="always")
def _add_d(st, c, x, own):
    if own:
        st.d[c] += x
    else:
        atomic_add(st.d, c, x)


@nb.njit(cache=True, inline="always")
def _add_inf(st, inf32, c, which, x, own):
    """The count of infinite terms of cell ``c`` (``which`` 0: ``pos``, 1: ``neg``) plus ``x``."""
    if own:
        if which == 0:
            st.inf[c].pos += x
        else:
            st.inf[c].neg += x
    else:
        atomic_add(inf32, 2 * c + which, np.int32(x))


@nb.njit(cache=True, inline="always")
def _add_term(st, inf32, c, r, x, y, sign, geo):
    a = st.ll[r, x]
    b = st.ll[r, y]
    own = _own(c, geo[0], geo[1], geo[2], geo[3], geo[4])
    if not st.any_inf:
        _add_d(st, c, sign * (cs._q(a, st.scale) - cs._q(b, st.scale)), own)
    elif a > -np.inf:
        if b > -np.inf:
            _add_d(st, c, sign * (cs._q(a, st.scale) - cs._q(b, st.scale)), own)
        else:
            _add_inf(st, inf32, c, 0, sign, own)
    elif b > -np.inf:
        _add_inf(st, inf32, c, 1, sign, own)


@nb.njit(cache=True, inline="always")
def _ray_term(st, inf32, r, kap, f, s, sign, geo):
    c = st.cells[st.offsets[r] + kap]
    if kap < f:
        _add_term(st, inf32, c, r, kap, f, sign, geo)
    elif kap == f:
        _add_term(st, inf32, c, r, f, s, sign, geo)


@nb.njit(cache=True, inline="always")
def _retarget(st, inf32, r, f1, s1, geo):
    f0 = st.rays[r].f
    s0 = st.rays[r].s
    st.rays[r].f = f1
    st.rays[r].s = s1
    a = st.offsets[r]
    n = st.offsets[r + 1] - a
    if f0 == f1:
        if s0 != s1 and f0 < n:
            c = st.cells[a + f0]
            _add_term(st, inf32, c, r, f0, s1, 1, geo)
            _add_term(st, inf32, c, r, f0, s0, -1, geo)
        return
    lo = min(f0, f1)
    b0 = st.ll[r, f0]
    b1 = st.ll[r, f1]
    if not st.any_inf:  # the ray's runs of cells in one tile: plain adds in the updating tile's, atomic elsewhere
        delta = cs._q(b0, st.scale) - cs._q(b1, st.scale)
        t, seg_off, seg_start, seg_tile = geo[5], geo[6], geo[7], geo[8]
        j1 = seg_off[r + 1]
        for j in range(seg_off[r], j1):
            x0 = seg_start[j]
            if x0 >= lo:
                break
            x1 = min(seg_start[j + 1] if j + 1 < j1 else n, lo)
            if seg_tile[j] == t:
                for kap in range(x0, x1):
                    st.d[st.cells[a + kap]] += delta
            else:
                for kap in range(x0, x1):
                    atomic_add(st.d, st.cells[a + kap], delta)
    elif b0 > -np.inf and b1 > -np.inf:
        delta = cs._q(b0, st.scale) - cs._q(b1, st.scale)
        cols, r0, c0, T, inv_cols = geo[0], geo[1], geo[2], geo[3], geo[4]
        for kap in range(lo):
            if not st.ll[r, kap] > -np.inf:
                continue
            c = st.cells[a + kap]
            _add_d(st, c, delta, _own(c, cols, r0, c0, T, inv_cols))
    else:
        for kap in range(lo):
            c = st.cells[a + kap]
            _add_term(st, inf32, c, r, kap, f1, 1, geo)
            _add_term(st, inf32, c, r, kap, f0, -1, geo)
    for kap in range(lo, min(max(f0, f1), n - 1) + 1):
        _ray_term(st, inf32, r, kap, f1, s1, 1, geo)
        _ray_term(st, inf32, r, kap, f0, s0, -1, geo)


@nb.njit(cache=True, inline="always")
def _set_cell(st, inf32, k, v, geo):
    # one call site of the inlined _retarget (four, as in cell_sweep._set_cell, make compilation explode)
    st.m[k] = v
    for p in range(st.c_off[k], st.c_off[k + 1]):
        r = st.c_ray[p]
        kap = st.c_kappa[p]
        f = st.rays[r].f
        s = st.rays[r].s
        if v:
            if kap < f:
                f1, s1 = kap, f
            elif kap < s:
                f1, s1 = f, kap
            else:
                continue
        elif kap == f:
            n = st.offsets[r + 1] - st.offsets[r]
            f1, s1 = s, (_next_occupied(st.m, st.offsets, st.cells, r, s + 1) if s < n else n)
        elif kap == s:
            f1, s1 = f, _next_occupied(st.m, st.offsets, st.cells, r, kap + 1)
        else:
            continue
        _retarget(st, inf32, r, f1, s1, geo)


@njit_shipped
def tile_pass(st, inf32, prior, lay, t, seed, scan, update):
    """The updates of tile ``t``'s short cells in one sweep of seed ``seed``: its order and uniforms from
    the stream :func:`tile_seed` (``scan``: a code of :func:`~ogm_ppl.inference._kernels.cell_sweep.draws`),
    each cell drawn by ``update`` (heat bath / metropolised). Safe to run beside the other tiles of its
    colour (module docstring). Returns the flips."""
    order, u = cs.draws(lay.tile_cells[lay.tile_off[t] : lay.tile_off[t + 1]], scan, tile_seed(seed, t))
    geo = (
        lay.cols,
        (t // lay.n_tc) * lay.T,
        (t % lay.n_tc) * lay.T,
        lay.T,
        1.0 / lay.cols,
        np.int64(t),
        lay.seg_off,
        lay.seg_start,
        lay.seg_tile,
    )
    return _tile_loop(st, inf32, prior, order, u, geo, update)


@njit_shipped(_nrt=False)
def _tile_loop(st, inf32, prior, order, u, geo, update):
    """The loop of :func:`tile_pass` (without numba's runtime, as
    :func:`~ogm_ppl.inference._kernels.cell_sweep.sweep`: it allocates nothing)."""
    m = st.m
    flips = 0
    for i in range(order.shape[0]):
        k = order[i]
        lo = cell_log_odds(prior, k, m) + cs._lik_ratio(st, k)
        cur = m[k]
        v = cs.new_value(lo, u[i], cur, update)
        if v != cur:
            _set_cell(st, inf32, k, v, geo)
            flips += 1
    return flips


@njit_shipped
def long_pass(st, prior, lay, seed, scan, update):
    """The updates of the long cells, one after another (the stream of ``t = n_tiles``). Returns the flips."""
    order, u = cs.draws(lay.long_cells, scan, tile_seed(seed, lay.n_tr * lay.n_tc))
    return cs.sweep(st, order, prior, u, update)


@nb.njit(cache=True, inline="always")
def take_tile(taken, n):
    """The next of a colour's ``n`` tiles (ordered costliest first) for the thread that asks: one shared
    counter ``taken[0]`` read and advanced atomically (:func:`fetch_add`), so the threads share a colour
    phase as list scheduling does, whichever of them runs slower at the moment (numba's ``prange`` would
    split the tiles into fixed blocks). Which thread runs a tile does not change the chain: the tiles of a
    colour touch disjoint state, and each draws from its own stream. Returns ``n`` or more when none is left."""
    return fetch_add(taken, 0, np.int64(1)) if n > 0 else n


@njit_shipped(parallel=True)
def chromatic_sweep(st, inf32, prior, lay, seed, scan, update, threads):
    """One chromatic sweep (module docstring): for each colour, its tiles' :func:`tile_pass` in parallel
    (``numba.prange`` over ``threads`` workers, numba's threads: pass ``numba.get_num_threads()``), then
    :func:`long_pass`. ``inf32`` is ``st.inf`` viewed as int32 (``pos``, ``neg`` of cell ``c`` at ``2c``,
    ``2c + 1``). Returns the flips. (``threads`` is an argument, not ``numba.get_num_threads()`` read inside:
    that call compiles to a process address, which would keep the kernel out of numba's on-disk cache.)"""
    total = 0
    P = max(threads, 1)
    for colour in range(COLOURS):
        a = lay.col_off[colour]
        n = lay.col_off[colour + 1] - a
        flips = np.zeros(n, np.int64)
        taken = np.zeros(1, np.int64)
        for _ in nb.prange(P):  # each thread takes the costliest tile left until none is (take_tile)
            j = take_tile(taken, n)
            while j < n:
                flips[j] = tile_pass(st, inf32, prior, lay, lay.col_tiles[a + j], seed, scan, update)
                j = take_tile(taken, n)
        total += flips.sum()
    return total + long_pass(st, prior, lay, seed, scan, update)
