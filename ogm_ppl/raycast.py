"""Exact ray traversal of a grid into a compact ray -> cells structure (Section 2.4).

Each reading ``z_n`` becomes a ray: the cells ``m_kappa``, ``kappa = 0..F_n``, that the beam from pose
``x_n`` enters before the sensor's maximum range, ordered from the sensor outward (``kappa = 0`` is the
cell holding the sensor) and cut at the grid edge. The rays are stored CSR-style:

* ``offsets`` (``R + 1``, int64) and ``cells`` (int64): ray ``r`` visits ``cells[offsets[r]:offsets[r+1]]``;
* ``t_enter`` (float32): distance, in cells, from the sensor to where the beam enters each cell;
* ``z`` (int64): the reading in kappa units (the convention below; counted on past the grid edge when
  the reading lies outside the grid; equal to the ray's cell count for max-range readings);
* ``is_max``: the reading is a max-range reading; ``endpoint_in_grid``;
* ``reading`` (int64): the flat beam index (``scan * B + beam``) each ray came from. Beams that are not
  readings (``Scans.valid`` False: no return, below minimum range) get no ray.
* ``range_len`` (int64): the cells the ray would enter before the sensor's maximum range on an unbounded
  grid (``F_n + 1`` of the sensor; equal to the ray's length unless the grid edge cut it);
* ``geometry`` (``R x 5`` float64): start ``u0, v0`` and direction ``du, dv`` in continuous cell units and
  the maximum range in cells, from which :meth:`Rays.entries_beyond_edge` recomputes the entry distances
  of the cells past the grid edge.

**The range convention (one for the whole library).** Physically a beam returns where it *enters* the
first occupied cell, at its near face. A metric range ``r`` therefore becomes the kappa of the cell whose
entry point is nearest to ``r``: ray cell ``kappa`` owns the ranges between the midpoints
``(t_{kappa-1} + t_kappa) / 2`` and ``(t_kappa + t_{kappa+1}) / 2`` of consecutive entry distances
(ties go to the nearer cell; a reading past the last entry midpoint inside the range belongs to the last
cell). A noise-free reading of a wall entered at kappa ``f`` gives ``z = f`` exactly, and symmetric range
noise gives readings whose kappa averages ``f``: the sensor models centre ``p(z | f)`` on ``f``
(:mod:`ogm_ppl.sensors`), and :func:`~ogm_ppl.datasets.simulate_scans` measures ranges to the near face.

In 1D the ray is the row of cells from the robot outward; from a robot in the middle of cell 0, cell
``kappa >= 1`` is entered at ``kappa - 1/2``, so a wall at ``f`` reads ``f - 1/2`` metres (1 m cells).
The thesis's integer toy readings ``z`` are the kappa values themselves (:func:`~ogm_ppl.datasets.toy_1d`
converts them to near-face ranges).

The transposed index cell -> (ray, kappa), needed by Gibbs sampling (Section 4.1.2), is built on first
use by :attr:`Rays.by_cell`.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from typing import NamedTuple

import numpy as np

from ogm_ppl._raycast_kernels import RayArrays, entries_beyond, entry_positions, transpose_csr, traverse_all
from ogm_ppl.grid import Grid
from ogm_ppl.scans import Scans

__all__ = ["CellIndex", "RayCastSize", "RayIndex", "RayInputs", "Rays", "ray_cast_size", "ray_inputs", "raycast"]


@dataclass(frozen=True)
class CellIndex:
    """Transposed index: cell ``k`` is crossed by rays ``ray[offsets[k]:offsets[k+1]]`` at position
    ``kappa[offsets[k]:offsets[k+1]]`` along each (ordered by ray)."""

    offsets: np.ndarray
    ray: np.ndarray
    kappa: np.ndarray


class RayIndex(NamedTuple):
    """What the compiled likelihood kernels walk, in one bundle (numba takes it as one argument): the rays
    in CSR form, the transposed cell -> (ray, kappa) index and the likelihood table ``ll[r, kappa] =
    log p(z_r | first hit at kappa)`` (column ``len(r)``: no hit). Built by :meth:`Rays.index`."""

    offsets: np.ndarray  # R + 1 int64: CSR along rays
    cells: np.ndarray  # nnz int64: cells of each ray in kappa order
    c_off: np.ndarray  # K + 1 int64: CSR by cell
    c_ray: np.ndarray  # nnz int64: the rays through each cell
    c_kappa: np.ndarray  # nnz int64: the cell's position on each of them
    ll: np.ndarray  # R x (F + 1) float64


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
    reading: np.ndarray | None = None
    range_len: np.ndarray | None = None
    geometry: np.ndarray | None = None

    def __post_init__(self) -> None:
        if self.reading is None:
            object.__setattr__(self, "reading", np.arange(self.num_rays, dtype=np.int64))
        if self.range_len is None:
            object.__setattr__(self, "range_len", self.lengths.copy())

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

    def max_range_cells(self) -> np.ndarray:
        """The sensor's maximum range of every ray, in cells (``R``)."""
        if self.geometry is None:
            return self.lengths.astype(np.float64)
        return self.geometry[:, 4]

    def entries_beyond_edge(self, rays: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Entry distances (cells) of the cells past the grid edge before max range, for the given rays:
        CSR ``(offsets, t)`` with ``range_len - lengths`` entries per ray."""
        rays = np.asarray(rays, dtype=np.int64)
        if self.geometry is None:
            raise ValueError("these Rays carry no geometry; build them with raycast()")
        g = self.geometry[rays]
        return entries_beyond(
            g[:, 0].copy(),
            g[:, 1].copy(),
            g[:, 2].copy(),
            g[:, 3].copy(),
            g[:, 4].copy(),
            self.lengths[rays].astype(np.int64),
        )

    def ray(self, r: int) -> np.ndarray:
        """Cells of ray ``r``, from the sensor outward."""
        return self.cells[self.offsets[r] : self.offsets[r + 1]]

    @cached_property
    def by_cell(self) -> CellIndex:
        """The transposed index cell -> (ray, kappa)."""
        off, ray, kap = transpose_csr(self.offsets, self.cells, self.grid.num_cells)
        return CellIndex(off, ray, kap)

    def index(self, loglik_table) -> RayIndex:
        """The :class:`RayIndex` of these rays with the likelihood table ``loglik_table`` (``R x (F + 1)``)."""
        idx = self.by_cell
        ll = np.ascontiguousarray(np.asarray(loglik_table), dtype=np.float64)
        return RayIndex(self.offsets, self.cells, idx.offsets, idx.ray, idx.kappa, ll)

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
    reading: np.ndarray

    def capacity(self) -> int:
        """Upper bound on the cells of any ray (also on the kappa of any reading)."""
        L = self.length.max(initial=0.0)
        return int(np.floor(L * np.abs(self.du)).max(initial=0) + np.floor(L * np.abs(self.dv)).max(initial=0)) + 3

    def arrays(self) -> RayArrays:
        """The rays as the traversal kernels take them (``t_hit``: ``range_cells``)."""
        return RayArrays(self.u0, self.v0, self.du, self.dv, self.length, self.range_cells, self.is_max)


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
        raise ValueError(f"Scans.poses[{s}] = {scans.poses[s].tolist()} lies outside the grid (extent {grid.extent})")
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
    assert scans.valid is not None  # Scans.__post_init__ always sets the S x B mask
    keep = np.flatnonzero(scans.valid.ravel())
    n = keep.shape[0]
    return RayInputs(
        u0=np.repeat(uv[:, 0], B)[keep],
        v0=np.repeat(uv[:, 1], B)[keep],
        du=np.ascontiguousarray(du[keep]),
        dv=np.ascontiguousarray(dv[keep]),
        length=np.full(n, scans.max_range / grid.resolution),
        range_cells=scans.ranges.ravel()[keep] / grid.resolution,
        is_max=np.ascontiguousarray(scans.is_max.ravel()[keep]),
        reading=keep.astype(np.int64),
    )


#: bytes :func:`raycast` allocates for each cell a ray may enter (its cell index, int64, and entry distance,
#: float32), and for each ray (offsets, reading, flags, range length and the ``R x 5`` float64 geometry)
CAST_BYTES_PER_CELL, CAST_BYTES_PER_RAY = 12, 8 + 8 + 1 + 8 + 8 + 40


class RayCastSize(NamedTuple):
    """What a ray cast of some scans on a grid will hold, known before it runs (:func:`ray_cast_size`)."""

    rays: int  # R: the valid readings
    capacity: int  # the cells :func:`raycast` makes room for: every ray up to the sensor's maximum range
    crossings: int  # an upper bound on the ray-cell entries it finds (each ray cut at the grid edge)
    longest: int  # an upper bound on the cells of one ray

    @property
    def cast_bytes(self) -> int:
        """Bytes the ray cast allocates (its buffers stay allocated while the :class:`Rays` live)."""
        return self.capacity * CAST_BYTES_PER_CELL + self.rays * CAST_BYTES_PER_RAY


def ray_cast_size(grid: Grid, scans: Scans) -> RayCastSize:
    """The sizes of ``raycast(grid, scans)`` without casting (a pass of NumPy over the rays): the capacity the
    cast allocates (:func:`~ogm_ppl._raycast_kernels.ray_capacity` of each ray's maximum range) and a bound on
    the ray-cell entries (the same bound on each ray's segment inside the grid). Raises as :func:`raycast` does
    for a pose off the grid."""
    ri = ray_inputs(grid, scans)
    adu, adv = np.abs(ri.du), np.abs(ri.dv)
    cap = np.floor(ri.length * adu) + np.floor(ri.length * adv) + 3
    rows = grid.rows if grid.ndim == 2 else 1
    with np.errstate(divide="ignore", invalid="ignore"):
        tu = np.where(ri.du > 0, (grid.cols - ri.u0) / ri.du, np.where(ri.du < 0, ri.u0 / -ri.du, np.inf))
        tv = np.where(ri.dv > 0, (rows - ri.v0) / ri.dv, np.where(ri.dv < 0, ri.v0 / -ri.dv, np.inf))
    inside = np.minimum(ri.length, np.minimum(tu, tv))
    cut = np.minimum(np.floor(inside * adu) + np.floor(inside * adv) + 3, cap)
    return RayCastSize(
        rays=int(ri.length.shape[0]),
        capacity=int(cap.sum()),
        crossings=int(cut.sum()),
        longest=int(cut.max(initial=0)),
    )


def raycast(grid: Grid, scans: Scans) -> Rays:
    """Traverse every reading of ``scans`` through ``grid`` (Amanatides-Woo, exact).

    Rays are cut at ``scans.max_range`` (cells entered at a distance ``< max_range``) and at the grid edge;
    beams with ``scans.valid`` False get no ray.

    Raises:
        ValueError: a pose outside the grid (names the scan index), or a 1D grid with a beam that is not
            along the row.

    >>> from ogm_ppl import Grid, Scans
    >>> rays = raycast(Grid.line(10), Scans.one_d([3.0, 5.0], max_range=5.0))
    >>> rays.ray(0).tolist(), int(rays.z[0]), bool(rays.is_max[1])
    ([0, 1, 2, 3, 4, 5], 3, True)
    """
    ri = ray_inputs(grid, scans)
    offsets, cells, t_enter, z, in_grid, range_len = traverse_all(ri.arrays(), grid.rows, grid.cols)
    return Rays(
        grid=grid,
        offsets=offsets,
        cells=cells,
        t_enter=t_enter,
        z=z,
        is_max=ri.is_max,
        endpoint_in_grid=in_grid,
        range_cells=ri.range_cells,
        reading=ri.reading,
        range_len=range_len,
        geometry=np.stack([ri.u0, ri.v0, ri.du, ri.dv, ri.length], axis=1),
    )
