"""Numba kernels for exact grid traversal (Amanatides & Woo, 1987).

Coordinates are continuous cell units: ``u`` along columns (x), ``v`` along rows (y). A ray starts at
``(u0, v0)`` with unit direction ``(du, dv)``. The crossing parameters of the next column / row boundary
are computed directly from the start point at every step (``t = (boundary - u0) / du``), never accumulated,
so the visited cells do not drift with rounding; ties (a ray through a grid corner) step the column first,
which keeps consecutive cells 4-connected.
"""

from __future__ import annotations

import numba as nb
import numpy as np

_INF = np.inf


@nb.njit(cache=True, inline="always")
def _axis_setup(p0: float, d: float):
    """Cell index, step and first boundary of one axis."""
    c = int(np.floor(p0))
    if d > 0.0:
        return c, 1, c + 1.0, 1.0 / d
    if d < 0.0:
        return c, -1, float(c), 1.0 / d
    return c, 0, 0.0, 0.0


@nb.njit(cache=True, inline="always")
def _t_cross(boundary: float, p0: float, inv: float, step: int) -> float:
    if step == 0:
        return _INF
    return (boundary - p0) * inv


@nb.njit(cache=True)
def traverse_all(u0, v0, du, dv, length, t_hit, is_max, rows, cols):
    """Traverse every ray; return the CSR arrays.

    Args (all 1D arrays of the number of rays R, except ``rows``/``cols``):
        u0, v0: start in continuous cell coordinates (inside the grid).
        du, dv: unit direction.
        length: max range in cells; a ray keeps the cells it enters at ``t < length``.
        t_hit: reading in cells (ignored where ``is_max``).

    Returns:
        offsets (R+1 int64), cells (int64), t_enter (float32), z (int64: kappa of the reading's cell,
        counted on past the grid edge for hits outside the grid; the ray's cell count for max-range
        readings), endpoint_in_grid (bool).
    """
    R = u0.shape[0]
    caps = np.empty(R + 1, np.int64)
    caps[0] = 0
    for r in range(R):
        L = length[r]
        caps[r + 1] = caps[r] + int(np.floor(L * abs(du[r]))) + int(np.floor(L * abs(dv[r]))) + 3
    buf_cells = np.empty(caps[R], np.int64)
    buf_t = np.empty(caps[R], np.float32)
    counts = np.zeros(R, np.int64)
    z = np.empty(R, np.int64)
    in_grid = np.zeros(R, np.bool_)
    for r in range(R):
        col, sx, bx, ix = _axis_setup(u0[r], du[r])
        row, sy, by, iy = _axis_setup(v0[r], dv[r])
        L = length[r]
        th = t_hit[r]
        mx = is_max[r]
        tx = _t_cross(bx, u0[r], ix, sx)
        ty = _t_cross(by, v0[r], iy, sy)
        base = caps[r]
        n = 0
        t = 0.0
        zr = -1
        while True:
            buf_cells[base + n] = row * cols + col
            buf_t[base + n] = t
            if not mx and t <= th:
                zr = n
            n += 1
            # leave the current cell
            if tx <= ty:
                t = tx
                col += sx
                bx += sx
                tx = _t_cross(bx, u0[r], ix, sx)
            else:
                t = ty
                row += sy
                by += sy
                ty = _t_cross(by, v0[r], iy, sy)
            if t >= L:
                break
            if col < 0 or col >= cols or row < 0 or row >= rows:
                # left the grid: for a hit beyond the edge, count on to the reading's kappa
                if not mx and t <= th:
                    k = n
                    while True:
                        zr = k
                        k += 1
                        if tx <= ty:
                            t = tx
                            bx += sx
                            tx = _t_cross(bx, u0[r], ix, sx)
                        else:
                            t = ty
                            by += sy
                            ty = _t_cross(by, v0[r], iy, sy)
                        if t > th or t >= L:
                            break
                break
        counts[r] = n
        if mx:
            z[r] = n
        else:
            z[r] = zr
            in_grid[r] = zr < n
    offsets = np.empty(R + 1, np.int64)
    offsets[0] = 0
    for r in range(R):
        offsets[r + 1] = offsets[r] + counts[r]
    cells = np.empty(offsets[R], np.int64)
    t_enter = np.empty(offsets[R], np.float32)
    for r in range(R):
        a = caps[r]
        o = offsets[r]
        for j in range(counts[r]):
            cells[o + j] = buf_cells[a + j]
            t_enter[o + j] = buf_t[a + j]
    return offsets, cells, t_enter, z, in_grid


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
