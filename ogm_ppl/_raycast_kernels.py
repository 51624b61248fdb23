"""Numba kernels for exact grid traversal (Amanatides & Woo, 1987).

Coordinates are continuous cell units: ``u`` along columns (x), ``v`` along rows (y). A ray starts at
``(u0, v0)`` with unit direction ``(du, dv)``. The crossing parameter of the next column / row boundary
is computed directly from the start point at every step (``t = (boundary - u0) / du``, a division so
that subnormal directions cannot give ``0 * inf``), never accumulated, so the visited cells do not drift
with rounding; ties (a ray through a grid corner) step the column first, which keeps consecutive cells
4-connected.

:func:`trace_ray` walks one ray into a small scratch buffer; :func:`traverse_all` (the CSR builder)
and the fused traditional-OGM kernel in :mod:`ogm_ppl.inference._kernels.log_odds` both use it.
"""

from __future__ import annotations

from typing import NamedTuple

import numba as nb
import numpy as np

_INF = np.inf


class RayArrays(NamedTuple):
    """The rays a traversal walks, as 1D arrays over the ``R`` rays (one numba argument)."""

    u0: np.ndarray  # R float64: start column, continuous cell coordinates (inside the grid)
    v0: np.ndarray  # R float64: start row
    du: np.ndarray  # R float64: unit direction, along columns
    dv: np.ndarray  # R float64: unit direction, along rows
    length: np.ndarray  # R float64: max range in cells; a ray keeps the cells it enters at t < length
    t_hit: np.ndarray  # R float64: the reading in cells (ignored where is_max)
    is_max: np.ndarray  # R bool: max-range reading


@nb.njit(cache=True, inline="always")
def _axis_setup(p0: float, d: float):
    """Cell index, step and first boundary of one axis."""
    c = int(np.floor(p0))
    if d > 0.0:
        return c, 1, c + 1.0
    if d < 0.0:
        return c, -1, float(c)
    return c, 0, 0.0


@nb.njit(cache=True, inline="always")
def _t_cross(boundary: float, p0: float, d: float, step: int) -> float:
    if step == 0:
        return _INF
    return (boundary - p0) / d


@nb.njit(cache=True, inline="always")
def ray_capacity(length: float, du: float, dv: float) -> int:
    """An upper bound on the cells a ray of ``length`` cells can enter."""
    return int(np.floor(length * abs(du))) + int(np.floor(length * abs(dv))) + 3


@nb.njit(cache=True, inline="always")
def trace_ray(rays, r, rows, cols, out_cells, out_t, base, count_all):
    """Walk ray ``r`` of ``rays`` (:class:`RayArrays`), writing its in-grid cells and entry distances at
    ``out_*[base:]``.

    The reading ``th = rays.t_hit[r]`` (cells) belongs to the cell whose entry distance is nearest to it (the range
    convention of :mod:`ogm_ppl.raycast`; ties go to the nearer cell); past the grid edge the kappa is
    counted on. With ``count_all`` the walk also counts the cells beyond the edge up to max range.

    Returns ``(n, z, n_range)``: the cells in the grid before max range, the reading's kappa (``n`` for a
    max-range reading) and, with ``count_all``, the cells the ray enters before max range on an unbounded
    grid (else a lower bound).
    """
    u0, v0, du, dv = rays.u0[r], rays.v0[r], rays.du[r], rays.dv[r]
    L, th, mx = rays.length[r], rays.t_hit[r], rays.is_max[r]
    col, sx, bx = _axis_setup(u0, du)
    row, sy, by = _axis_setup(v0, dv)
    tx = _t_cross(bx, u0, du, sx)
    ty = _t_cross(by, v0, dv, sy)
    n = 0
    k = 0
    t = 0.0
    t_prev = 0.0
    zr = -1
    inside = True
    while True:
        if inside:
            out_cells[base + n] = row * cols + col
            out_t[base + n] = t
            n += 1
        if not mx and (k == 0 or 0.5 * (t_prev + t) < th):
            zr = k
        t_prev = t
        if tx <= ty:
            t = tx
            col += sx
            bx += sx
            tx = _t_cross(bx, u0, du, sx)
        else:
            t = ty
            row += sy
            by += sy
            ty = _t_cross(by, v0, dv, sy)
        if t >= L:
            break
        k += 1
        if inside and (col < 0 or col >= cols or row < 0 or row >= rows):
            inside = False
        if not inside and not count_all and (mx or 0.5 * (t_prev + t) >= th):
            break
    if mx:
        zr = n
    return n, zr, k + 1


@nb.njit(cache=True)
def traverse_all(rays, rows, cols):
    """Traverse every ray of ``rays`` (:class:`RayArrays`) on a ``rows x cols`` grid; return the CSR arrays.

    Returns:
        offsets (R+1 int64), cells (int64), t_enter (float32), z (int64), endpoint_in_grid (bool),
        range_len (int64: cells before max range on an unbounded grid).
    """
    R = rays.u0.shape[0]
    length, du, dv, is_max = rays.length, rays.du, rays.dv, rays.is_max
    total = 0
    cap_max = 1
    for r in range(R):
        c = ray_capacity(length[r], du[r], dv[r])
        total += c
        cap_max = max(cap_max, c)
    cells = np.empty(total, np.int64)
    t_enter = np.empty(total, np.float32)
    offsets = np.empty(R + 1, np.int64)
    z = np.empty(R, np.int64)
    in_grid = np.zeros(R, np.bool_)
    range_len = np.empty(R, np.int64)
    offsets[0] = 0
    for r in range(R):
        n, zr, nr = trace_ray(rays, r, rows, cols, cells, t_enter, offsets[r], True)
        offsets[r + 1] = offsets[r] + n
        z[r] = zr
        in_grid[r] = (not is_max[r]) and zr < n
        range_len[r] = nr
    nnz = offsets[R]
    return offsets, cells[:nnz], t_enter[:nnz], z, in_grid, range_len


@nb.njit(cache=True)
def entries_beyond(u0, v0, du, dv, length, skip):
    """Entry distances of the cells a ray enters before ``length`` on an unbounded grid, from kappa
    ``skip[r]`` on (the cells past the grid edge), CSR over the rays: ``(offsets, t)``."""
    R = u0.shape[0]
    offsets = np.zeros(R + 1, np.int64)
    total = 0
    for r in range(R):
        total += ray_capacity(length[r], du[r], dv[r])
    out = np.empty(total, np.float64)
    for r in range(R):
        _, sx, bx = _axis_setup(u0[r], du[r])
        _, sy, by = _axis_setup(v0[r], dv[r])
        tx = _t_cross(bx, u0[r], du[r], sx)
        ty = _t_cross(by, v0[r], dv[r], sy)
        t = 0.0
        k = 0
        p = offsets[r]
        while t < length[r]:
            if k >= skip[r]:
                out[p] = t
                p += 1
            if tx <= ty:
                t = tx
                bx += sx
                tx = _t_cross(bx, u0[r], du[r], sx)
            else:
                t = ty
                by += sy
                ty = _t_cross(by, v0[r], dv[r], sy)
            k += 1
        offsets[r + 1] = p
    return offsets, out[: offsets[R]]


@nb.njit(cache=True)
def entry_positions(offsets):
    """Ray and kappa of every CSR entry."""
    R = offsets.shape[0] - 1
    ray = np.empty(offsets[R], np.int64)
    kappa = np.empty(offsets[R], np.int64)
    for r in range(R):
        for j in range(offsets[r], offsets[r + 1]):
            ray[j] = r
            kappa[j] = j - offsets[r]
    return ray, kappa


@nb.njit(cache=True)
def transpose_csr(offsets, cells, num_cells):
    """Cell -> (ray, kappa) index by counting sort: entries of a cell are ordered by ray."""
    R = offsets.shape[0] - 1
    nnz = cells.shape[0]
    cell_offsets = np.zeros(num_cells + 1, np.int64)
    for j in range(nnz):
        cell_offsets[cells[j] + 1] += 1
    for c in range(num_cells):
        cell_offsets[c + 1] += cell_offsets[c]
    fill = cell_offsets[:-1].copy()
    ray_ids = np.empty(nnz, np.int64)
    kappas = np.empty(nnz, np.int32)
    for r in range(R):
        for j in range(offsets[r], offsets[r + 1]):
            c = cells[j]
            p = fill[c]
            ray_ids[p] = r
            kappas[p] = j - offsets[r]
            fill[c] = p + 1
    return cell_offsets, ray_ids, kappas
