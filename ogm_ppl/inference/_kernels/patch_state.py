"""The state of a patch Gibbs sweep and how a patch is placed on it and written (Section 4.2).

The state is a :class:`PatchState`: the map ``m`` (uint8, ``K``), every ray's first occupied kappa ``f``
(kept in step with ``m`` by :func:`set_patch`), the scratch of ray collection, and the ray index
(:class:`~ogm_ppl.raycast.RayIndex`) it walks. A patch is the shape ``(dr, dc)`` of a :class:`PatchGeometry`
placed at an anchor (:func:`build_patch`: ``-1`` pads cells cut by the grid edge or pinned); its
configuration ``w`` has bit ``j`` set when its ``j``-th live cell is occupied (:func:`patch_config`).
:class:`PatchRule` says how an update chooses among the configurations. Ray collection marks the rays of an
update with a stamp never used before (:func:`_next_stamp`).
"""

from __future__ import annotations

from typing import NamedTuple

import numba as nb
import numpy as np

from ogm_ppl.inference._kernels.cells import _next_occupied


class PatchState(NamedTuple):
    """The map and first hits a patch sweep reads and writes, its ray-collection scratch, and the ray
    index it walks (the fields of :class:`~ogm_ppl.raycast.RayIndex`)."""

    m: np.ndarray  # K uint8: the map
    f: np.ndarray  # R int64: every ray's first occupied kappa (its length if none)
    in_patch: np.ndarray  # K bool, all False between updates
    ray_stamp: np.ndarray  # R x 2 int64: (stamp, slot) of a ray collected for the update with that stamp
    stamp: np.ndarray  # 1 int64: the next unused stamp
    offsets: np.ndarray  # R + 1 int64: CSR along rays
    cells: np.ndarray  # nnz int64
    c_off: np.ndarray  # K + 1 int64: CSR by cell
    c_ray: np.ndarray  # nnz int64
    c_kappa: np.ndarray  # nnz int64
    ll: np.ndarray  # R x (F + 1) float64
    max_deg: int  # the most rays through one cell (bounds a patch's rays: L max_deg)


def patch_state(m: np.ndarray, f: np.ndarray, index) -> PatchState:
    """The :class:`PatchState` over the map ``m`` and first hits ``f`` (views: kept in step in place)."""
    R = len(index.offsets) - 1
    return PatchState(
        m,
        f,
        np.zeros(len(m), np.bool_),
        np.full((R, 2), -1, np.int64),
        np.zeros(1, np.int64),
        index.offsets,
        index.cells,
        index.c_off,
        index.c_ray,
        index.c_kappa,
        index.ll,
        int(np.diff(index.c_off).max(initial=0)),
    )


class PatchGeometry(NamedTuple):
    """A patch shape on the grid: cell offsets ``(dr, dc)`` from the anchor, its ``h x w`` rectangle (0, 0
    if not a rectangle), the grid size and the pinned (known-free) cells."""

    dr: np.ndarray  # L int64
    dc: np.ndarray  # L int64
    h: int
    w: int
    rows: int
    cols: int
    pinned: np.ndarray  # K uint8


class PatchRule(NamedTuple):
    """How a patch update chooses: Algorithm 2's probability of a random configuration (accepted by
    Metropolis-Hastings unless ``thesis_random``), Liu's metropolised Gibbs or heat bath, the most
    candidate configurations an update may weigh, the probability of the escape move of a restricted
    candidate set (:func:`_candidate_sweep`), and ``own_factor`` (the thesis's border update of Section
    5.2.3: a tile drawn from its own table times the likelihood, the neighbouring tiles' factors
    ignored; not a Gibbs sampler of the tiled joint)."""

    p_rand_patch: float
    thesis_random: bool
    metropolised: bool
    capacity: int
    p_escape: float = 0.0
    own_factor: bool = False


@nb.njit(cache=True, inline="always")
def _next_stamp(ps, n):
    """Reserve ``n`` fresh stamps; returns the first."""
    s = ps.stamp[0]
    ps.stamp[0] = s + n
    return s


@nb.njit(cache=True)
def patch_config(patch, m):
    w = 0
    bit = 0
    for i in range(patch.shape[0]):
        c = patch[i]
        if c < 0:
            continue
        if m[c]:
            w |= 1 << bit
        bit += 1
    return w


@nb.njit(cache=True, inline="always")
def _set_cell(ps, k, v):
    """``m[k] = v``, updating the first hits of the rays through ``k``."""
    m, f = ps.m, ps.f
    if m[k] == v:
        return
    m[k] = v
    for p in range(ps.c_off[k], ps.c_off[k + 1]):
        r = ps.c_ray[p]
        kap = ps.c_kappa[p]
        if v:
            if kap < f[r]:
                f[r] = kap
        elif f[r] == kap:
            f[r] = _next_occupied(m, ps.offsets, ps.cells, r, kap + 1)


@nb.njit(cache=True)
def set_patch(ps, patch, w):
    """Set the live cells of ``patch`` to configuration ``w`` (bit ``j``: the ``j``-th live cell)."""
    bit = 0
    for i in range(patch.shape[0]):
        c = patch[i]
        if c < 0:
            continue
        _set_cell(ps, c, (w >> bit) & 1)
        bit += 1


@nb.njit(cache=True, inline="always")
def build_patch(geo, r0, c0, patch):
    """Cells of the patch ``geo`` placed at row ``r0``, column ``c0`` (which may lie off the grid);
    ``-1`` where a cell is off the grid or pinned. Returns the number of live cells."""
    dr, dc, pinned, rows, cols = geo.dr, geo.dc, geo.pinned, geo.rows, geo.cols
    n = 0
    for j in range(dr.shape[0]):
        r = r0 + dr[j]
        c = c0 + dc[j]
        if 0 <= r < rows and 0 <= c < cols and not pinned[r * cols + c]:
            patch[j] = r * cols + c
            n += 1
        else:
            patch[j] = -1
    return n


@nb.njit(cache=True)
def build_patch_at(geo, r0, c0, patch):
    """:func:`build_patch`, callable from Python."""
    return build_patch(geo, r0, c0, patch)
