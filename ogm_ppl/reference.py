"""Plain, obviously-correct implementations: the yardsticks of the tests and benchmarks.

Nothing here is fast. :func:`traverse_reference` finds a ray's cells by listing *every* column and row
boundary the ray crosses before its end, sorting the crossings, and stepping once per crossing (ties
step the column first, the same convention as the compiled kernel). :func:`evidence_grid_reference` is
traditional OGM one ray at a time in pure Python, locating the reading's cell geometrically (the cell
holding the end point), independently of the traversal's kappa count. :func:`evidence_grid_numpy` is the
batched, vectorised numpy version that a careful user would write without a compiler.
"""

from __future__ import annotations

import math

import numpy as np

from .grid import Grid
from .scans import Scans

__all__ = ["traverse_reference", "evidence_grid_reference", "evidence_grid_numpy"]


def _crossings(p0: float, d: float, length: float) -> list[float]:
    if d == 0.0:
        return []
    c = math.floor(p0)
    step, b = (1, c + 1.0) if d > 0 else (-1, float(c))
    out = []
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
    events = [(t, 0) for t in _crossings(u0, du, length)] + [
        (t, 1) for t in _crossings(v0, dv, length)
    ]
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
    return (
        np.repeat(uv[:, 0], B),
        np.repeat(uv[:, 1], B),
        du,
        dv,
        scans.ranges.ravel() / grid.resolution,
        scans.is_max.ravel(),
        scans.max_range / grid.resolution,
    )


def evidence_grid_reference(
    grid: Grid, scans: Scans, l_occ: float, l_free: float, prior: float = 0.5
) -> np.ndarray:
    """Moravec/Hähnel traditional OGM, one ray at a time in plain Python (Eq. 2.10)."""
    ev = np.full(grid.num_cells, math.log(prior / (1 - prior)))
    u0, v0, du, dv, rng, is_max, L = _rays_of(grid, scans)
    for r in range(len(u0)):
        cells, _ = traverse_reference(u0[r], v0[r], du[r], dv[r], L, grid.rows, grid.cols)
        end = None
        if not is_max[r]:
            eu, ev_ = u0[r] + rng[r] * du[r], v0[r] + rng[r] * dv[r]
            end = math.floor(ev_) * grid.cols + math.floor(eu)
        for c in cells:
            if c == end:
                ev[c] += l_occ
                break
            ev[c] += l_free
    return ev


def evidence_grid_numpy(
    grid: Grid, scans: Scans, l_occ: float, l_free: float, prior: float = 0.5, chunk: int = 4096
) -> np.ndarray:
    """Moravec/Hähnel traditional OGM, batched and vectorised in numpy (traversal included).

    Every ray's column and row crossings are computed as one array, sorted per ray (column first on
    ties), turned into cells by cumulative steps, cut at the grid edge and max range, and the updates
    summed with ``np.bincount``.
    """
    u0, v0, du, dv, rng, is_max, L = _rays_of(grid, scans)
    ev = np.zeros(grid.num_cells)
    rows, cols = grid.rows, grid.cols
    with np.errstate(divide="ignore", invalid="ignore"):
        for a in range(0, len(u0), chunk):
            s = slice(a, a + chunk)
            parts, steps = [], []
            for p0, d in ((u0[s], du[s]), (v0[s], dv[s])):
                n = int(np.floor(L * np.abs(d)).max()) + 2
                c0 = np.floor(p0)
                sgn = np.sign(d)
                first = np.where(d > 0, c0 + 1, c0)
                b = first[:, None] + sgn[:, None] * np.arange(n)[None, :]
                t = (b - p0[:, None]) / d[:, None]
                t[~np.isfinite(t) | (t >= L)] = np.inf
                parts.append(t)
                steps.append(np.broadcast_to(sgn[:, None], t.shape))
            t = np.concatenate(parts, axis=1)
            is_y = np.concatenate([np.zeros(parts[0].shape), np.ones(parts[1].shape)], axis=1)
            order = np.argsort(t, axis=1, kind="stable")
            t = np.take_along_axis(t, order, 1)
            is_y = np.take_along_axis(is_y, order, 1).astype(bool)
            st = np.take_along_axis(np.concatenate(steps, axis=1), order, 1)
            col = np.floor(u0[s])[:, None] + np.cumsum(np.where(is_y, 0, st), axis=1)
            row = np.floor(v0[s])[:, None] + np.cumsum(np.where(is_y, st, 0), axis=1)
            col = np.concatenate([np.floor(u0[s])[:, None], col], axis=1).astype(np.int64)
            row = np.concatenate([np.floor(v0[s])[:, None], row], axis=1).astype(np.int64)
            t = np.concatenate([np.zeros((t.shape[0], 1)), t], axis=1)
            out = (col < 0) | (col >= cols) | (row < 0) | (row >= rows) | ~np.isfinite(t)
            valid = ~np.maximum.accumulate(out, axis=1)
            before = t <= rng[s][:, None]
            # the reading's cell is the last one entered at or before the end point
            zk = np.where(is_max[s], 10**9, before.sum(axis=1) - 1)[:, None]
            k = np.arange(t.shape[1])[None, :]
            val = np.where(k < zk, l_free, np.where(k == zk, l_occ, 0.0))
            keep = valid & (val != 0)
            ev += np.bincount((row * cols + col)[keep], weights=val[keep], minlength=grid.num_cells)
    return ev + math.log(prior / (1 - prior))
