"""Plain, obviously-correct implementations: the yardsticks of the tests and benchmarks.

Nothing here is fast. :func:`traverse_reference` finds a ray's cells by listing *every* column and row
boundary the ray crosses before its end, sorting the crossings, and stepping once per crossing (ties
step the column first, the same convention as the compiled kernel). :func:`evidence_grid_reference` is
traditional OGM one ray at a time in pure Python, locating the reading's cell from the sorted list of
every entry distance (the cell whose entry is nearest the reading, :mod:`ogm_ppl.raycast`), independently
of the compiled traversal. :func:`evidence_grid_numpy` is the
batched, vectorised numpy version that a careful user would write without a compiler.
"""

from __future__ import annotations

import math

import numpy as np

from ogm_ppl.grid import Grid
from ogm_ppl.scans import Scans

__all__ = ["traverse_reference", "evidence_grid_reference", "evidence_grid_numpy"]


def _crossings(p0: float, d: float, length: float) -> list[float]:
    if d == 0.0:
        return []
    c = math.floor(p0)
    step, b = (1, c + 1.0) if d > 0 else (-1, float(c))
    out: list[float] = []
    while True:
        t = (b - p0) / d
        if t >= length:
            return out
        out.append(t)
        b += step


def traverse_reference(
    u0: float, v0: float, du: float, dv: float, length: float, rows: int, cols: int
) -> tuple[list[int], list[float]]:
    """Cells (flat, row-major) and entry distances of one ray; see the module docstring."""
    u0, v0, du, dv = float(u0), float(v0), float(du), float(dv)
    events = [(t, 0) for t in _crossings(u0, du, length)] + [(t, 1) for t in _crossings(v0, dv, length)]
    events.sort()  # by t, then column (0) before row (1)
    col, row = math.floor(u0), math.floor(v0)
    sx = int(du > 0) - int(du < 0)
    sy = int(dv > 0) - int(dv < 0)
    cells, ts = [row * cols + col], [0.0]
    for t, axis in events:
        if axis == 0:
            col += sx
        else:
            row += sy
        if not (0 <= col < cols and 0 <= row < rows):
            break
        cells.append(row * cols + col)
        ts.append(t)
    return cells, ts


def _rays_of(grid: Grid, scans: Scans):
    theta = scans.world_angles().ravel()
    uv = grid.world_to_continuous(scans.poses[:, :2])
    B = scans.beams_per_scan
    du, dv = np.cos(theta), np.sin(theta)
    if grid.ndim == 1:
        du, dv = np.sign(du), np.zeros_like(dv)
    assert scans.valid is not None  # Scans.__post_init__ always sets the S x B mask
    keep = scans.valid.ravel()
    return (
        np.repeat(uv[:, 0], B)[keep],
        np.repeat(uv[:, 1], B)[keep],
        du[keep],
        dv[keep],
        scans.ranges.ravel()[keep] / grid.resolution,
        scans.is_max.ravel()[keep],
        scans.max_range / grid.resolution,
    )


def reading_kappa_reference(u0: float, v0: float, du: float, dv: float, length: float, r: float) -> int:
    """Kappa of a reading ``r`` (cells) on an unbounded grid: the cell whose entry distance is nearest
    to ``r`` (ties to the nearer cell), from the sorted list of every boundary crossing before ``length``."""
    ts = [0.0] + sorted(_crossings(float(u0), float(du), length) + _crossings(float(v0), float(dv), length))
    z = 0
    for k in range(1, len(ts)):
        if 0.5 * (ts[k - 1] + ts[k]) < r:
            z = k
    return z


def evidence_grid_reference(grid: Grid, scans: Scans, l_occ: float, l_free: float, prior: float = 0.5) -> np.ndarray:
    """Moravec/Hähnel traditional OGM, one ray at a time in plain Python (Eq. 2.10)."""
    ev = np.full(grid.num_cells, math.log(prior / (1 - prior)))
    u0, v0, du, dv, rng, is_max, L = _rays_of(grid, scans)
    for r in range(len(u0)):
        cells, _ = traverse_reference(u0[r], v0[r], du[r], dv[r], L, grid.rows, grid.cols)
        z = len(cells) if is_max[r] else reading_kappa_reference(u0[r], v0[r], du[r], dv[r], L, rng[r])
        for kappa, c in enumerate(cells):
            if kappa == z:
                ev[c] += l_occ
                break
            ev[c] += l_free
    return ev


def evidence_grid_numpy(grid: Grid, scans: Scans, l_occ: float, l_free: float, prior: float = 0.5) -> np.ndarray:
    """Moravec/Hähnel traditional OGM, batched and vectorised in numpy (traversal included).

    A batched DDA: all rays advance one cell per step together (vector operations over the rays still
    inside the grid and range), the visited cells and their update terms are collected per step and
    summed once with ``np.bincount``. Same crossing formula and tie rule as the compiled kernel.
    """
    u0, v0, du, dv, rng, is_max, L = _rays_of(grid, scans)
    rows, cols = grid.rows, grid.cols
    col = np.floor(u0).astype(np.int64)
    row = np.floor(v0).astype(np.int64)
    sx = np.sign(du).astype(np.int64)
    sy = np.sign(dv).astype(np.int64)
    bx = np.where(du > 0, col + 1.0, col.astype(float))
    by = np.where(dv > 0, row + 1.0, row.astype(float))
    with np.errstate(divide="ignore", invalid="ignore"):
        tx = np.where(sx != 0, (bx - u0) / du, np.inf)
        ty = np.where(sy != 0, (by - v0) / dv, np.inf)
    t = np.zeros_like(u0)
    t_prev = np.full_like(u0, -np.inf)
    th = np.where(is_max, np.inf, rng)
    idx = np.arange(len(u0))
    done_hit = np.zeros(len(u0), dtype=bool)
    all_cells, all_vals = [], []
    while idx.size:
        # the current cell of every live ray: free before the reading's cell, occupied at it
        nxt = np.minimum(tx, ty)
        # the reading belongs to the cell whose entry distance is nearest to it (ogm_ppl.raycast)
        at_end = np.isfinite(th) & (0.5 * (t_prev + t) < th) & ((0.5 * (t + nxt) >= th) | (nxt >= L))
        val = np.where(at_end, l_occ, l_free)
        all_cells.append(row * cols + col)
        all_vals.append(val)
        done_hit[idx[at_end]] = True
        step_x = tx <= ty
        t_prev = t
        t = np.where(step_x, tx, ty)
        col = col + np.where(step_x, sx, 0)
        row = row + np.where(step_x, 0, sy)
        with np.errstate(invalid="ignore"):
            bx = bx + np.where(step_x, sx, 0)
            by = by + np.where(step_x, 0, sy)
            tx = np.where(step_x & (sx != 0), (bx - u0) / np.where(du == 0, 1, du), tx)
            ty = np.where(~step_x & (sy != 0), (by - v0) / np.where(dv == 0, 1, dv), ty)
        live = (t < L) & ~at_end & (col >= 0) & (col < cols) & (row >= 0) & (row < rows)
        idx, col, row, sx, sy, bx, by, tx, ty, t, t_prev, th, u0, v0, du, dv = (
            a[live] for a in (idx, col, row, sx, sy, bx, by, tx, ty, t, t_prev, th, u0, v0, du, dv)
        )
    ev = np.bincount(np.concatenate(all_cells), weights=np.concatenate(all_vals), minlength=grid.num_cells)
    return ev + math.log(prior / (1 - prior))


def gibbs_cell_sweep_reference(model, m: np.ndarray, cells_order, uniforms, prior_log_odds) -> np.ndarray:
    """One single-cell Gibbs sweep in plain Python (Eq. 4.2): for every cell, every ray through it is
    walked from the sensor to find its first occupied cell with the cell occupied and free.

    ``m`` (uint8 ``K``) is updated in place and returned.
    """
    rays = model.rays
    idx = rays.by_cell
    ll = model.loglik_table.numpy()
    offsets, cells = rays.offsets.tolist(), rays.cells.tolist()

    def first(r):
        for j in range(offsets[r], offsets[r + 1]):
            if m[cells[j]]:
                return j - offsets[r]
        return offsets[r + 1] - offsets[r]

    for k, u in zip(cells_order, uniforms):
        k = int(k)
        saved = m[k]
        lo = float(prior_log_odds[k])
        for p in range(idx.offsets[k], idx.offsets[k + 1]):
            r = int(idx.ray[p])
            m[k] = 1
            f1 = first(r)
            m[k] = 0
            f0 = first(r)
            lo += ll[r, f1] - ll[r, f0]
        m[k] = saved
        p1 = 1.0 / (1.0 + math.exp(-lo)) if lo > -700 else 0.0
        m[k] = 1 if u < p1 else 0
    return m
