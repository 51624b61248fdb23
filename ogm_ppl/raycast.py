"""Exact ray traversal of a grid into a compact ray -> cells structure (Section 2.4).

Each reading ``z_n`` becomes a ray: the cells ``m_kappa``, ``kappa = 0..F_n``, that the beam from pose
``x_n`` enters before the sensor's maximum range, ordered from the sensor outward (``kappa = 0`` is the
cell holding the sensor) and cut at the grid edge. The rays are stored CSR-style:

* ``offsets`` (``R + 1``, int64) and ``cells`` (int64): ray ``r`` visits ``cells[offsets[r]:offsets[r+1]]``;
* ``t_enter`` (float32): distance, in cells, from the sensor to where the beam enters each cell;
* ``z`` (int64): the reading in kappa units, i.e. the kappa of the cell holding the beam's end point
  (counted on past the grid edge when the end point lies outside the grid; equal to the ray's cell count
  for max-range readings, which have no end point);
* ``is_max``: the reading is a max-range (no return) reading; ``endpoint_in_grid``.

In 1D the ray is the row of cells from the robot outward; a robot in the middle of cell 0 with integer
readings gives ``z_n`` equal to the reading, as in the thesis's toy problems.

The transposed index cell -> (ray, kappa), needed by Gibbs sampling (Section 4.1.2), is built on first
use by :attr:`Rays.by_cell`.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from ._raycast_kernels import entry_positions, transpose_csr, traverse_all
from .grid import Grid
from .scans import Scans

__all__ = ["Rays", "CellIndex", "RayInputs", "ray_inputs", "raycast"]


@dataclass(frozen=True)
class CellIndex:
    """Transposed index: cell ``k`` is crossed by rays ``ray[offsets[k]:offsets[k+1]]`` at position
    ``kappa[offsets[k]:offsets[k+1]]`` along each (ordered by ray)."""

    offsets: np.ndarray
    ray: np.ndarray
    kappa: np.ndarray


@dataclass(frozen=True, eq=False)
class Rays:
    """Every reading's ray through the grid, in CSR form (see the module docstring).

    Shapes: ``R`` rays, ``nnz = offsets[-1]`` ray-cell entries.
    """

    grid: Grid
    offsets: np.ndarray
    cells: np.ndarray
    t_enter: np.ndarray
    z: np.ndarray
    is_max: np.ndarray
    endpoint_in_grid: np.ndarray
    range_cells: np.ndarray

    @property
    def num_rays(self) -> int:
        """R."""
        return self.offsets.shape[0] - 1

    @property
    def nnz(self) -> int:
        """Total number of ray-cell entries."""
        return int(self.offsets[-1])

    @property
    def lengths(self) -> np.ndarray:
        """Cells per ray (``F_n + 1``), ``R``."""
        return np.diff(self.offsets)

    @cached_property
    def _entries(self) -> tuple[np.ndarray, np.ndarray]:
        return entry_positions(self.offsets)

    @property
    def kappa(self) -> np.ndarray:
        """Position of every entry along its ray (``nnz``, int64)."""
        return self._entries[1]

    @property
    def ray_of_entry(self) -> np.ndarray:
        """Ray of every entry (``nnz``, int64)."""
        return self._entries[0]

    def ray(self, r: int) -> np.ndarray:
        """Cells of ray ``r``, from the sensor outward."""
        return self.cells[self.offsets[r] : self.offsets[r + 1]]

    @cached_property
    def by_cell(self) -> CellIndex:
        """The transposed index cell -> (ray, kappa)."""
        off, ray, kap = transpose_csr(self.offsets, self.cells, self.grid.num_cells)
        return CellIndex(off, ray, kap)

    def reached(self) -> np.ndarray:
        """Boolean ``K``: cells some beam reached (entered at or before its end point, or anywhere
        along a max-range ray). Cells no beam reached are *unknown*, kept apart from *free*."""
        mask = np.zeros(self.grid.num_cells, dtype=bool)
        keep = self.kappa <= self.z[self.ray_of_entry]
        mask[self.cells[keep]] = True
        return mask

    def endpoint_cells(self) -> np.ndarray:
        """Cells holding a beam's end point (hits inside the grid), one entry per such ray."""
        rr = np.flatnonzero(self.endpoint_in_grid)
        return self.cells[self.offsets[rr] + self.z[rr]]


@dataclass(frozen=True)
class RayInputs:
    """Per-ray start, direction, length and reading in continuous cell units (validated)."""

    u0: np.ndarray
    v0: np.ndarray
    du: np.ndarray
    dv: np.ndarray
    length: np.ndarray
    range_cells: np.ndarray
    is_max: np.ndarray

    def capacity(self) -> int:
        """Upper bound on the cells of any ray (also on the kappa of any reading)."""
        L = self.length.max(initial=0.0)
        return int(np.floor(L * np.abs(self.du)).max(initial=0) + np.floor(L * np.abs(self.dv)).max(initial=0)) + 3


def ray_inputs(grid: Grid, scans: Scans) -> RayInputs:
    """Check the poses against ``grid`` and express every reading's ray in cell units.

    Raises:
        ValueError: a pose outside the grid (names the scan index), or a 1D grid with a beam that is not
            along the row.
    """
    xy = scans.poses[:, :2]
    inside = grid.contains(xy)
    if grid.ndim == 1:
        ok_y = np.abs(xy[:, 1] - grid.origin[1]) <= grid.resolution
        inside &= ok_y
    if not inside.all():
        s = int(np.flatnonzero(~inside)[0])
        raise ValueError(
            f"Scans.poses[{s}] = {scans.poses[s].tolist()} lies outside the grid "
            f"(extent {grid.extent})"
        )
    theta = scans.world_angles().ravel()
    du = np.cos(theta)
    dv = np.sin(theta)
    if grid.ndim == 1:
        bad = np.abs(dv) > 1e-9
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            raise ValueError(
                f"on a 1D grid every beam must point along the row (yaw + angle = 0 or pi); "
                f"reading {i} points at {theta[i]} rad"
            )
        dv = np.zeros_like(dv)
        du = np.sign(du)
    B = scans.beams_per_scan
    uv = grid.world_to_continuous(xy)
    n = scans.num_readings
    return RayInputs(
        u0=np.repeat(uv[:, 0], B),
        v0=np.repeat(uv[:, 1], B),
        du=du,
        dv=dv,
        length=np.full(n, scans.max_range / grid.resolution),
        range_cells=scans.ranges.ravel() / grid.resolution,
        is_max=np.ascontiguousarray(scans.is_max.ravel()),
    )


def raycast(grid: Grid, scans: Scans) -> Rays:
    """Traverse every reading of ``scans`` through ``grid`` (Amanatides-Woo, exact).

    Rays are cut at ``scans.max_range`` (cells entered at a distance ``< max_range``) and at the grid edge.

    Raises:
        ValueError: a pose outside the grid (names the scan index), or a 1D grid with a beam that is not
            along the row.

    >>> from ogm_ppl import Grid, Scans
    >>> rays = raycast(Grid.line(10), Scans.one_d([3.0, 5.0], max_range=5.0))
    >>> rays.ray(0).tolist(), int(rays.z[0]), bool(rays.is_max[1])
    ([0, 1, 2, 3, 4, 5], 3, True)
    """
    ri = ray_inputs(grid, scans)
    offsets, cells, t_enter, z, in_grid = traverse_all(
        ri.u0, ri.v0, ri.du, ri.dv, ri.length, ri.range_cells, ri.is_max, grid.rows, grid.cols
    )
    return Rays(
        grid=grid,
        offsets=offsets,
        cells=cells,
        t_enter=t_enter,
        z=z,
        is_max=ri.is_max,
        endpoint_in_grid=in_grid,
        range_cells=ri.range_cells,
    )
