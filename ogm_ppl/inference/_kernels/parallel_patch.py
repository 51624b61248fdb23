r"""Chromatic patch sweeps: patch Gibbs updates (Algorithms 1 and 2) of many tiles of the grid at once, exactly.

The colouring of :mod:`~ogm_ppl.inference._kernels.parallel` applied to patches. The grid is cut into
``T x T`` tiles from an origin ``(o_r, o_c)`` (both ``<= 0``: the patch tiling's first start, so that with
``T`` a multiple of the patch's height and width every patch of the tiling lies in one tile), coloured
``2 (a mod 2) + (b mod 2)``. A patch is *short* when its live cells lie in one tile and every ray through them
is confined (at most one tile of each colour), else *long*; ``T`` must be at least every prior factor's extent.

**Why a phase is exact.** The update of a patch ``A`` draws ``A``'s configuration from its full conditional
(or a Metropolis-Hastings / escape move that keeps it invariant), which reads the factors with a cell in
``A``: the rays through ``A`` and the prior's factors touching ``A``. For short patches ``A`` and ``B`` in
distinct tiles of one colour, no factor touches both: a ray through both would not be confined, and a prior
factor holding cells of two tiles of one colour has extent ``> T`` (the rule's proof in
:mod:`~ogm_ppl.inference._kernels.parallel`). So ``B``'s cells are outside ``A``'s Markov blanket, the two
updates commute, and updating the short patches of all tiles of one colour at once (each tile's patches in
turn) gives exactly the map of the serial composition, in any order of the tiles: each phase is a
composition of ``pi``-invariant patch updates, and so is the sweep (the four phases, then the long patches in
turn).

**No data race.** A patch update writes the map at its own cells and the first hits ``f`` of the rays
through them (confined: no other tile of the colour touches them), the ray-collection stamps of those rays,
the ``in_patch`` and ``bit_of`` scratch at its own cells, and per-update scratch that each tile allocates
for itself; the stamps are reserved for the whole sweep before it starts (patch ``j`` of the layout has
``base + j``), so no counter is shared. Reads outside the tile are of cells no concurrent update writes.

**Random numbers.** Tile ``t`` draws its patches' order and uniforms from the SplitMix64 stream
:func:`~ogm_ppl.inference._kernels.parallel.tile_seed` of the sweep seed, the long patches from the stream of
``t = n_tiles``: the chain is a function of its seed, the same for every thread count.
"""

from __future__ import annotations

from typing import NamedTuple

import numba as nb
import numpy as np

from ogm_ppl._numba_cache import njit_shipped
from ogm_ppl.inference._kernels import cell_sweep as cs
from ogm_ppl.inference._kernels import parallel as par
from ogm_ppl.inference._kernels.patch_state import _next_stamp
from ogm_ppl.inference._kernels.patch_sweep import patch_pass

__all__ = ["PatchTileLayout", "chromatic_patch_sweep", "patch_draws", "patch_tile_layout"]


class PatchTileLayout(NamedTuple):
    """The tiles of a chromatic patch sweep: ``T x T`` tiles from ``(o_r, o_c)`` (``n_tr x n_tc``, tile
    ``t = a n_tc + b``), the short patches' anchors grouped by tile (CSR ``tile_off`` / ``anchors``, in the
    kernel's fixed order within a tile), the non-empty tiles of each colour (CSR ``col_off`` / ``col_tiles``,
    costlier first) and the long patches' anchors, updated last."""

    T: int
    o_r: int
    o_c: int
    n_tr: int
    n_tc: int
    tile_off: np.ndarray  # n_tiles + 1 int64
    anchors: np.ndarray  # n_short x 2 int64
    col_off: np.ndarray  # COLOURS + 1 int64
    col_tiles: np.ndarray  # int64
    long_anchors: np.ndarray  # n_long x 2 int64

    @property
    def n_tiles(self) -> int:
        return self.n_tr * self.n_tc


def patch_tile_layout(
    anchors: np.ndarray, patch_cells: np.ndarray, index, rows: int, cols: int, T: int, origin: tuple[int, int]
) -> PatchTileLayout:
    """The :class:`PatchTileLayout` of the patches at ``anchors`` (``n x 2``, in the kernel's order) whose cells
    are ``patch_cells`` (``n x L``, ``-1`` where none), over the rays of ``index`` (a
    :class:`~ogm_ppl.raycast.RayIndex`), on ``T x T`` tiles from ``origin``."""
    if T < 1:
        raise ValueError(f"the tile side must be at least 1 cell, got {T}")
    o_r, o_c = int(origin[0]), int(origin[1])
    if o_r > 0 or o_c > 0:
        raise ValueError(f"the tiles' origin must be <= 0, got {origin}")
    n_tr, n_tc = -(-(rows - o_r) // T), -(-(cols - o_c) // T)
    K = rows * cols
    confined = par.confined_rays(index.offsets, index.cells, cols, T, n_tc, o_r, o_c)
    long_cell = np.append(par._long_mask(K, index.offsets, index.cells, confined), False)  # [-1]: no cell
    live = patch_cells >= 0
    r, c = np.divmod(np.where(live, patch_cells, 0), cols)
    tile = np.where(live, ((r - o_r) // T) * n_tc + (c - o_c) // T, -1)
    first = tile.max(1)  # the tile of a live cell (every patch here has one)
    inside = np.where(live, tile == first[:, None], True).all(1)
    short = inside & ~long_cell[patch_cells].any(1)
    ids = first[short]
    order = np.argsort(ids, kind="stable")
    anchors_short = np.ascontiguousarray(anchors[short][order], dtype=np.int64)
    counts = np.bincount(ids, minlength=n_tr * n_tc)
    tile_off = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    # a tile's cost ~ its patches' ray entries: dealt out largest first, so that threads share a phase evenly
    deg = np.append(np.diff(index.c_off), 0)[patch_cells].sum(1)[short][order]
    cost = np.bincount(ids[order], weights=deg + 1.0, minlength=n_tr * n_tc)
    nonempty = np.nonzero(counts)[0]
    colour = par.colour_of_tile(nonempty, n_tc)
    key = np.lexsort((-cost[nonempty], colour))
    return PatchTileLayout(
        int(T),
        o_r,
        o_c,
        int(n_tr),
        int(n_tc),
        tile_off,
        anchors_short,
        np.concatenate([[0], np.cumsum(np.bincount(colour, minlength=par.COLOURS))]).astype(np.int64),
        np.ascontiguousarray(nonempty[key].astype(np.int64)),
        np.ascontiguousarray(anchors[~short], dtype=np.int64),
    )


@nb.njit(cache=True)
def patch_draws(anchors, scan, seed, rows):
    """One group's patch order (``scan``: systematic or permutation, from the stream ``seed``) and its
    ``rows x n`` uniforms (from the stream after it, ``_splitmix64(seed)``)."""
    n = anchors.shape[0]
    idx = np.arange(n)
    order, _ = cs.draws(idx, scan, seed)
    out = np.empty((n, 2), np.int64)
    for i in range(n):
        out[i, 0] = anchors[order[i], 0]
        out[i, 1] = anchors[order[i], 1]
    s2 = cs._splitmix64(seed)
    u = np.empty((rows, n), np.float64)
    for q in range(rows):
        for i in range(n):
            u[q, i] = cs._uniform(s2, q * n + i)
    return out, u


class SweepDraws(NamedTuple):
    """How a chromatic patch sweep draws its patch orders and uniforms (one numba argument)."""

    seed: int  # the sweep's stream; tile t draws from par.tile_seed(seed, t)
    scan: int  # the patch order within a group (systematic or permutation: cell_sweep.draws)
    rows: int  # uniforms per patch (3, or 5 with the escape move)


@njit_shipped
def _tile_patches(ps, geo, lay, prior, dr, rule, bit_of, t, base):
    """The patch pass of tile ``t`` of ``lay``, its patches ordered and its uniforms drawn by ``dr``
    (:class:`SweepDraws`), stamps from ``base`` on."""
    lo, hi = lay.tile_off[t], lay.tile_off[t + 1]
    anchors, u = patch_draws(lay.anchors[lo:hi], dr.scan, par.tile_seed(dr.seed, t), dr.rows)
    return patch_pass(ps, geo, anchors, prior, u, rule, base + lo, bit_of)


@njit_shipped(parallel=True)
def chromatic_patch_sweep(ps, geo, lay, prior, seed, scan, rule, rows, bit_of, threads):
    """One chromatic patch sweep (module docstring): for each colour its tiles' patches (``numba.prange``
    over ``threads`` workers: pass ``numba.get_num_threads()``; see :func:`.parallel.chromatic_sweep`), then
    the long patches. ``rows``: uniforms per patch (3, or 5 with the escape move); ``bit_of``: the prior
    scratch's cell map (``K`` int64, all -1; empty for additive priors). Returns ``(changed, skipped)``."""
    n_short = lay.anchors.shape[0]
    base = _next_stamp(ps, n_short + lay.long_anchors.shape[0])
    changed = 0
    skipped = 0
    P = max(threads, 1)
    dr = SweepDraws(seed, scan, rows)
    for colour in range(par.COLOURS):
        a = lay.col_off[colour]
        n = lay.col_off[colour + 1] - a
        ch = np.zeros(n, np.int64)
        sk = np.zeros(n, np.int64)
        taken = np.zeros(1, np.int64)
        for _ in nb.prange(P):  # each thread takes the costliest tile left until none is (par.take_tile)
            j = par.take_tile(taken, n)
            while j < n:
                c, s = _tile_patches(ps, geo, lay, prior, dr, rule, bit_of, lay.col_tiles[a + j], base)
                ch[j] = c
                sk[j] = s
                j = par.take_tile(taken, n)
        changed += ch.sum()
        skipped += sk.sum()
    anchors, u = patch_draws(lay.long_anchors, scan, par.tile_seed(seed, lay.n_tr * lay.n_tc), rows)
    c, s = patch_pass(ps, geo, anchors, prior, u, rule, base + n_short, bit_of)
    return changed + c, skipped + s
