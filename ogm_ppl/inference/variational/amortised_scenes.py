"""Simulated scenes: poses and beams of 2D stop-and-scan datasets, the rays of the model whose joint
``p(m) p(z | m)`` inference compilation draws its training pairs ``(m, z)`` from (Section 2.1, 2.6).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from ogm_ppl.grid import Grid
from ogm_ppl.models.occupancy import OccupancyModel
from ogm_ppl.priors.base import MapPrior
from ogm_ppl.sensors import SensorModel

__all__ = ["Scene", "random_scene"]


@dataclass(frozen=True, eq=False)
class Scene:
    """Poses and beams of a simulated 2D stop-and-scan dataset (grid resolution 1, so ranges are in cells):
    the rays of the model whose joint ``p(m) p(z | m)`` inference compilation draws from.

    :meth:`model` builds the :class:`~ogm_ppl.OccupancyModel` of given readings (default: placeholders,
    all max range, for drawing ``(m, z)`` from its joint with ``prior.sample_given_free(model.known_free)``
    and :meth:`OccupancyModel.simulate_readings`).
    """

    grid: Grid
    poses: np.ndarray
    angles: np.ndarray
    max_range_cells: float
    sensor: SensorModel
    prior: MapPrior

    def model(self, readings: torch.Tensor | None = None) -> OccupancyModel:
        """The model of these poses with ``readings`` (``R = poses x beams`` values of site ``"z"``, scan by
        scan). Ranges below 0 (Gaussian noise near the sensor) are read as 0, the nearest range a
        :class:`~ogm_ppl.Scans` holds; both fall in the sensor's cell (kappa 0), so the guide's features
        are the same."""
        from ogm_ppl import Scans, raycast

        P, B = len(self.poses), len(self.angles)
        F = float(self.max_range_cells)
        if readings is None:
            ranges = np.full((P, B), F)
        else:
            z = torch.as_tensor(readings, dtype=torch.float64)
            if z.shape != (P * B,) or torch.isnan(z).any():
                raise ValueError(f"readings must be {P * B} numbers (poses x beams)")
            ranges = z.numpy().clip(0.0, F).reshape(P, B)
        scans = Scans(self.poses, self.angles, ranges, F)
        model = OccupancyModel(self.grid, raycast(self.grid, scans), self.sensor, self.prior)
        if model.rays.num_rays != P * B:
            raise RuntimeError("a beam got no ray")
        return model


def random_scene(
    prior: MapPrior,
    shape: tuple[int, int],
    num_poses: int,
    beams: int = 120,
    max_range_cells: float = 12.0,
    sensor: SensorModel | None = None,
    rng: np.random.Generator | None = None,
    free: np.ndarray | None = None,
) -> Scene:
    """``num_poses`` 360 degree scans (``beams`` each, range ``max_range_cells``) from poses drawn uniformly
    over the grid (over the ``free`` cells of a ``rows x cols`` mask when given), yaw 0, resolution 1.
    ``sensor`` defaults to ``GaussianRange(1.0)``."""
    from ogm_ppl import GaussianRange

    rng = np.random.default_rng() if rng is None else rng
    grid = Grid(tuple(int(s) for s in shape), resolution=1.0)
    if free is None:
        cells = np.stack([rng.integers(0, grid.rows, num_poses), rng.integers(0, grid.cols, num_poses)], 1)
    else:
        ok = np.flatnonzero(np.asarray(free, bool).ravel())
        if not len(ok):
            raise ValueError("no free cell to place a pose in")
        cells = np.stack(np.divmod(rng.choice(ok, num_poses), grid.cols), 1)
    xy = grid.cell_to_world(cells) + rng.uniform(-0.3, 0.3, (num_poses, 2))
    poses = np.c_[xy, np.zeros(num_poses)]
    angles = np.arange(beams) * (2 * np.pi / beams)
    return Scene(
        grid, poses, angles, float(max_range_cells), sensor if sensor is not None else GaussianRange(1.0), prior
    )
