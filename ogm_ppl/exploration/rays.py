"""The beams of candidate sensor poses, traversed through a grid once (:func:`candidate_rays`), and the
bundle of their arrays the compiled exploration kernels read (:class:`RayTable`).

Ray ``r = c * B + b`` is beam ``b`` of candidate ``c``; it visits the cells ``cells[offsets[r]:offsets[r+1]]``
(kappa ``0..len_r - 1`` from the sensor's cell outward, cut at the grid edge and at max range), each entered
``t_enter`` cells from the sensor (the convention of :mod:`ogm_ppl.raycast`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
import torch

from ogm_ppl._raycast_kernels import traverse_all
from ogm_ppl.grid import Grid
from ogm_ppl.raycast import ray_inputs
from ogm_ppl.scans import Scans

__all__ = ["CandidateRays", "RayTable", "candidate_rays", "check_rays", "ray_table", "refuse_blocked"]


@dataclass(frozen=True, eq=False)
class CandidateRays:
    """The beams of ``C`` candidate poses traversed through a grid once, reusable for many sample sets.

    Ray ``r = c * B + b`` is beam ``b`` of candidate ``c``; it visits ``cells[offsets[r]:offsets[r+1]]``
    (kappa ``0..len_r - 1`` from the sensor's cell outward, cut at the grid edge and at max range) entered at
    ``t_enter`` cells from the sensor (the convention of :mod:`ogm_ppl.raycast`).

    Attributes:
        grid: the grid.
        poses: ``C x 3`` float64 ``(x, y, yaw)``; ``beam_angles``: ``B`` float64; ``max_range``: metres.
        offsets: ``C*B + 1`` int64; ``cells``: int64; ``t_enter``: float32 (as :class:`~ogm_ppl.Rays`).
        range_len: ``C*B`` int64, the cells each ray enters before max range on an unbounded grid.
        pose_cells: ``C`` int64, the flat cell holding each candidate.
    """

    grid: Grid
    poses: np.ndarray
    beam_angles: np.ndarray
    max_range: float
    offsets: np.ndarray
    cells: np.ndarray
    t_enter: np.ndarray
    range_len: np.ndarray
    pose_cells: np.ndarray

    @property
    def num_candidates(self) -> int:
        """C."""
        return int(self.poses.shape[0])

    @property
    def num_beams(self) -> int:
        """B."""
        return int(self.beam_angles.shape[0])

    @property
    def lengths(self) -> np.ndarray:
        """Cells per ray in the grid, ``C*B``."""
        return np.diff(self.offsets)

    @property
    def max_range_cells(self) -> float:
        """The maximum range in cells (``F`` of a continuous sensor)."""
        return self.max_range / self.grid.resolution

    def ray(self, c: int, b: int) -> np.ndarray:
        """Cells of beam ``b`` of candidate ``c``, from the sensor outward."""
        r = c * self.num_beams + b
        return self.cells[self.offsets[r] : self.offsets[r + 1]]


def candidate_rays(
    grid: Grid, poses, beam_angles, max_range: float, occupied: np.ndarray | torch.Tensor | None = None
) -> CandidateRays:
    """Traverse the beams of candidate poses (exact, Amanatides-Woo, :func:`~ogm_ppl.raycast.raycast`).

    Args:
        grid: the grid of the map.
        poses: ``C x 3`` ``(x, y, yaw)`` in metres / radians (a ``3`` vector for one candidate).
        beam_angles: ``B`` beam angles relative to the yaw.
        max_range: the sensor's maximum range in metres.
        occupied: optional boolean ``K`` mask of cells known to be occupied (a known map, a thresholded
            one); a candidate in such a cell is refused.

    Raises:
        ValueError: no candidates, no beams, a non-finite pose or angle, ``max_range <= 0``, a candidate
            off the grid or inside an occupied cell (each naming the candidate).
    """
    P = np.asarray(poses, dtype=np.float64)
    if P.ndim == 1 and P.shape == (3,):
        P = P[None, :]
    if P.ndim != 2 or P.shape[1] != 3:
        raise ValueError(f"candidate poses must have shape C x 3 (x, y, yaw), got {P.shape}")
    if P.shape[0] == 0:
        raise ValueError("the candidate set is empty (poses has shape 0 x 3)")
    if not np.isfinite(P).all():
        raise ValueError(f"candidate pose {int(np.flatnonzero(~np.isfinite(P).all(1))[0])} is not finite")
    A = np.atleast_1d(np.asarray(beam_angles, dtype=np.float64))
    if A.ndim != 1 or A.shape[0] == 0:
        raise ValueError(f"beam_angles must be a non-empty vector, got shape {A.shape}")
    if not np.isfinite(A).all():
        raise ValueError("beam_angles holds a non-finite value")
    mr = float(max_range)
    if not (math.isfinite(mr) and mr > 0):
        raise ValueError(f"max_range must be a positive finite number of metres, got {max_range!r}")
    inside = grid.contains(P[:, :2])
    if grid.ndim == 1:
        inside &= np.abs(P[:, 1] - grid.origin[1]) <= grid.resolution
    if not inside.all():
        c = int(np.flatnonzero(~inside)[0])
        raise ValueError(f"candidate pose {c} = {P[c].tolist()} lies off the grid (extent {grid.extent})")
    rc = grid.world_to_cell(P[:, :2])
    pose_cells = np.asarray(grid.flat_index(rc), dtype=np.int64).reshape(-1)
    if occupied is not None:
        occ = np.asarray(occupied.cpu() if isinstance(occupied, torch.Tensor) else occupied).reshape(-1)
        if occ.shape != (grid.num_cells,):
            raise ValueError(f"occupied must be a mask of the grid's {grid.num_cells} cells, got shape {occ.shape}")
        hit = occ[pose_cells] != 0
        if hit.any():
            c = int(np.flatnonzero(hit)[0])
            raise ValueError(
                f"candidate pose {c} = {P[c].tolist()} lies inside an obstacle (cell {rc[c].tolist()} is occupied)"
            )
    scans = Scans(P, A, np.full((P.shape[0], A.shape[0]), mr), max_range=mr)
    try:
        ri = ray_inputs(grid, scans)
    except ValueError as e:  # a 1D grid with a beam off the row: name the candidate and beam
        B = A.shape[0]
        raise ValueError(f"candidate beams (reading i is candidate i // {B}, beam i % {B}): {e}") from e
    offsets, cells, t_enter, _, _, range_len = traverse_all(ri.arrays(), grid.rows, grid.cols)
    return CandidateRays(grid, P, A, mr, offsets, cells, t_enter, range_len, pose_cells)


class RayTable(NamedTuple):
    """The arrays of :class:`CandidateRays` the compiled kernels read (one numba argument).

    ``offsets`` ``C*B + 1`` int64, ``cells`` int64, ``t_enter`` float32 (ray ``r`` visits
    ``cells[offsets[r]:offsets[r+1]]``, entered at ``t_enter``), ``pose_cells`` ``C`` int64 (the flat cell of
    each candidate), ``num_beams`` ``B``.
    """

    offsets: np.ndarray
    cells: np.ndarray
    t_enter: np.ndarray
    pose_cells: np.ndarray
    num_beams: int


def ray_table(rays: CandidateRays) -> RayTable:
    """The kernels' :class:`RayTable` of ``rays``."""
    return RayTable(rays.offsets, rays.cells, rays.t_enter, rays.pose_cells, rays.num_beams)


def check_rays(grid: Grid, rays: CandidateRays) -> None:
    """``TypeError`` unless ``rays`` is a :class:`CandidateRays`, ``ValueError`` if cast on another grid."""
    if not isinstance(rays, CandidateRays):
        raise TypeError(f"candidate_rays must be a CandidateRays (from candidate_rays()), got {type(rays).__name__}")
    if rays.grid != grid:
        raise ValueError(f"candidate_rays were cast on another grid ({rays.grid}, not {grid})")


def refuse_blocked(rays: CandidateRays, blocked: np.ndarray, where: str) -> None:
    """``ValueError`` naming the first candidate with ``blocked`` set (its cell occupied in ``where``)."""
    if blocked.any():
        c = int(np.flatnonzero(blocked)[0])
        rc = rays.grid.world_to_cell(rays.poses[c : c + 1, :2])[0]
        raise ValueError(
            f"candidate pose {c} = {rays.poses[c].tolist()} lies inside an obstacle: its cell "
            f"{np.atleast_1d(rc).tolist()} is occupied in {where}"
        )
