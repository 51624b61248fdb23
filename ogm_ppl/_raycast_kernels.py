"""Numba kernels for exact grid traversal (Amanatides & Woo, 1987).

Coordinates are continuous cell units: ``u`` along columns (x), ``v`` along rows (y). A ray starts at
``(u0, v0)`` with unit direction ``(du, dv)``. The crossing parameter of the next column / row boundary
is computed directly from the start point at every step (``t = (boundary - u0) / du``, a division so
that subnormal directions cannot give ``0 * inf``), never accumulated, so the visited cells do not drift
with rounding; ties (a ray through a grid corner) step the column first, which keeps consecutive cells
4-connected.

:func:`trace_ray` walks one ray into a small scratch buffer; :func:`traverse_all` (the CSR builder)
and the fused traditional-OGM kernel in :mod:`ogm_ppl.inference._ogm_kernels` both use it.
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
def trace_ray(u0, v0, du, dv, L, th, mx, rows, cols, out_cells, out_t, base):
    """Walk one ray, writing its cells and entry distances at ``out_*[base:]``.

    Returns ``(n, z)``: the number of cells in the grid before max range, and the kappa of the cell
    holding the reading (counted on past the grid edge; ``n`` for a max-range reading).
    """
    col, sx, bx = _axis_setup(u0, du)
    row, sy, by = _axis_setup(v0, dv)
    tx = _t_cross(bx, u0, du, sx)
    ty = _t_cross(by, v0, dv, sy)
    n = 0
    t = 0.0
    zr = -1
    while True:
        out_cells[base + n] = row * cols + col
        out_t[base + n] = t
        if not mx and t <= th:
            zr = n
        n += 1
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
                        tx = _t_cross(bx, u0, du, sx)
                    else:
                        t = ty
                        by += sy
                        ty = _t_cross(by, v0, dv, sy)
                    if t > th or t >= L:
                        break
            break
    if mx:
        zr = n
    return n, zr


@nb.njit(cache=True)
def traverse_all(u0, v0, du, dv, length, t_hit, is_max, rows, cols):
    """Traverse every ray; return the CSR arrays.

    Args (1D arrays over the R rays, except ``rows``/``cols``):
        u0, v0: start in continuous cell coordinates (inside the grid).
        du, dv: unit direction.
        length: max range in cells; a ray keeps the cells it enters at ``t < length``.
        t_hit: reading in cells (ignored where ``is_max``).

    Returns:
        offsets (R+1 int64), cells (int64), t_enter (float32), z (int64), endpoint_in_grid (bool).
    """
    R = u0.shape[0]
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
    offsets[0] = 0
    for r in range(R):
        n, zr = trace_ray(u0[r], v0[r], du[r], dv[r], length[r], t_hit[r], is_max[r], rows, cols,
                          cells, t_enter, offsets[r])  # fmt: skip
        offsets[r + 1] = offsets[r] + n
        z[r] = zr
        in_grid[r] = (not is_max[r]) and zr < n
    nnz = offsets[R]
    return offsets, cells[:nnz], t_enter[:nnz], z, in_grid


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
