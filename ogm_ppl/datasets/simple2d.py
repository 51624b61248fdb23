"""A simple 2D example in the spirit of Fig. 2.8: a small walled map scanned from three poses.

The thesis gives the setting but not the map itself, so this map is ours: a 64 x 64 grid of 5 cm cells
with outer walls, a partition with a doorway, a free-standing block, and a closed room in the upper-right
corner that no beam reaches (as in Fig. 2.8b). Each pose takes 720 beams at 0.5 degree increments with
Gaussian range noise of ``sigma = 3`` cells; the maximum range (40 cells) leaves some beams without a
return.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ogm_ppl.datasets.simulate import simulate_scans
from ogm_ppl.grid import Grid
from ogm_ppl.scans import Scans

__all__ = ["SimpleExample2D", "simple_2d_example"]


@dataclass(frozen=True)
class SimpleExample2D:
    grid: Grid
    truth: np.ndarray
    scans: Scans
    sigma_cells: float


def _truth(n: int = 64) -> np.ndarray:
    m = np.zeros((n, n), dtype=bool)
    m[0, :] = m[-1, :] = m[:, 0] = m[:, -1] = True  # outer walls
    m[:, 30] = True  # partition ...
    m[12:20, 30] = False  # ... with a doorway
    m[8:13, 12:17] = True  # a block
    m[40:, 44] = True  # closed room, upper right (rows grow with y)
    m[40, 44:] = True
    m[24:26, 36:52] = True  # a wall segment in the right half
    return m


def simple_2d_example(
    sigma_cells: float = 3.0, max_range_cells: float = 40.0, seed: int = 0, num_beams: int = 720
) -> SimpleExample2D:
    """The example map, its three scan poses and simulated scans (seeded)."""
    res = 0.05
    truth = _truth()
    grid = Grid(truth.shape, resolution=res)
    poses = np.array([[8.5, 30.5, 0.0], [22.5, 8.5, 0.0], [40.5, 14.5, 0.0]]) * [res, res, 1.0]
    angles = np.arange(num_beams) * (2 * np.pi / num_beams)
    scans = simulate_scans(grid, truth, poses, angles, max_range_cells * res, sigma_cells, seed)
    return SimpleExample2D(grid, truth, scans, float(sigma_cells))
