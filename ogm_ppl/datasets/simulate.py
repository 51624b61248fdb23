"""Simulated range scans of a known binary map (ground truth), with Gaussian range noise.

A beam travels from the pose until it enters the first occupied cell; the true range is the distance at
which it enters that cell (0 if the sensor's own cell is occupied). The reported range is the true range
plus ``N(0, sigma^2)`` noise (``sigma`` in cells), floored at 0; readings at or beyond the maximum range,
and beams that meet no occupied cell inside the grid, are max-range readings.
"""

from __future__ import annotations

import numpy as np

from ogm_ppl.grid import Grid
from ogm_ppl.raycast import Rays, raycast
from ogm_ppl.scans import Scans

__all__ = ["first_hit", "simulate_scans"]


def first_hit(rays: Rays, occupancy: np.ndarray) -> np.ndarray:
    """Kappa of the first occupied cell on every ray, or the ray's length if none (``R`` int64)."""
    occ = np.asarray(occupancy, dtype=bool).ravel()[rays.cells]
    big = np.iinfo(np.int64).max
    key = np.where(occ, rays.kappa, big)
    first = np.minimum.reduceat(key, rays.offsets[:-1]) if rays.nnz else np.zeros(0, np.int64)
    return np.where(first == big, rays.lengths, first)


def simulate_scans(
    grid: Grid,
    truth: np.ndarray,
    poses: np.ndarray,
    angles: np.ndarray,
    max_range: float,
    sigma_cells: float,
    seed: int | np.random.Generator = 0,
) -> Scans:
    """Range scans of ``truth`` (a boolean map of ``grid.shape``) from ``poses`` (``S x 3``).

    A sensor sits in a free cell (the convention of :class:`~ogm_ppl.OccupancyModel`, which pins the cells
    holding a pose free): a pose in an occupied cell of ``truth`` is refused (``ValueError`` naming it).

    Args:
        angles: beam angles relative to the yaw (``B``).
        max_range: metres.
        sigma_cells: standard deviation of the range noise, in cells (>= 0; 0 gives exact ranges).
        seed: an int or a numpy Generator; the result is a deterministic function of it.
    """
    truth = np.asarray(truth, dtype=bool)
    if truth.shape != grid.shape:
        raise ValueError(f"truth has shape {truth.shape}, the grid {grid.shape}")
    if not sigma_cells >= 0:
        raise ValueError(f"sigma_cells must be >= 0, got {sigma_cells!r}")
    rng = np.random.default_rng(seed)
    poses = np.atleast_2d(np.asarray(poses, dtype=float))
    angles = np.asarray(angles, dtype=float)
    S, B = poses.shape[0], angles.shape[-1]
    probe = Scans(poses, angles, np.full((S, B), max_range), max_range)
    rays = raycast(grid, probe)
    own = rays.cells[rays.offsets[:-1]]
    inside = truth.ravel()[own]
    if inside.any():
        ray = int(np.flatnonzero(inside)[0])
        i = ray // max(B, 1)
        r, c = divmod(int(own[ray]), grid.shape[-1])
        raise ValueError(
            f"pose {i} ({poses[i, 0]:g}, {poses[i, 1]:g}) lies in occupied cell (row {r}, col {c}) of truth"
        )
    f = first_hit(rays, truth)
    hit = f < rays.lengths
    idx = np.minimum(f, rays.lengths - 1) + rays.offsets[:-1]
    true_range = np.where(hit, rays.t_enter[idx].astype(float), np.inf) * grid.resolution
    noisy = true_range + sigma_cells * grid.resolution * rng.standard_normal(true_range.shape)
    noisy = np.clip(noisy, 0.0, max_range)
    noisy[~hit] = max_range
    return Scans(poses, angles, noisy.reshape(S, B), max_range)
