"""The 1D toy problem of the thesis (Fig. 2.1): a stationary robot at cell 0, a wall at cell ``f``.

Readings are drawn from ``N(f, sigma^2)`` and rounded to whole cells (the thesis's readings are
integers); they are clipped to ``[0, max_range]``. The thesis's own six readings are
:data:`THESIS_TOY_READINGS` (``f = 8``, ``sigma = 3``).

Readings are in kappa units, as in the thesis: reading ``z`` is a beam that returned where it entered
cell ``z``, i.e. at range ``z - 1/2`` metres from the robot in the middle of cell 0 (the range convention
of :mod:`ogm_ppl.raycast`); a reading at ``max_range`` is a max-range reading.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ogm_ppl.grid import Grid
from ogm_ppl.scans import Scans

__all__ = ["Toy1D", "toy_1d", "THESIS_TOY_READINGS"]

#: z = {11, 7, 8, 8, 5, 9}: Fig. 2.1 and Fig. 2.9 (wall at f = 8, sigma = 3).
THESIS_TOY_READINGS = (11.0, 7.0, 8.0, 8.0, 5.0, 9.0)


@dataclass(frozen=True)
class Toy1D:
    """A 1D problem: grid of ``K`` cells (the robot in cell 0), readings in cells, the wall, truth."""

    grid: Grid
    scans: Scans
    readings: np.ndarray
    wall: int
    sigma: float

    @property
    def truth(self) -> np.ndarray:
        """The ground truth: free before the wall, occupied from the wall on (solid wall)."""
        m = np.zeros(self.grid.num_cells, dtype=bool)
        m[self.wall :] = True
        return m


def toy_1d(
    num_cells: int = 20,
    wall: int = 8,
    sigma: float = 3.0,
    num_readings: int = 6,
    seed: int | np.random.Generator = 0,
    readings=None,
    max_range: float | None = None,
) -> Toy1D:
    """A seeded 1D toy problem; pass ``readings`` to use given ones (e.g. the thesis's).

    ``max_range`` (cells) defaults to ``num_cells - 1``: the ray covers the whole grid.
    """
    if not 0 < wall < num_cells:
        raise ValueError(f"wall must lie in 1..{num_cells - 1}, got {wall}")
    if not sigma > 0:
        raise ValueError(f"sigma must be positive, got {sigma}")
    F = float(num_cells - 1 if max_range is None else max_range)
    if readings is None:
        rng = np.random.default_rng(seed)
        readings = np.rint(wall + sigma * rng.standard_normal(num_readings))
    readings = np.clip(np.asarray(readings, dtype=float), 0.0, F)
    grid = Grid.line(num_cells)
    ranges = np.where(readings >= F, F, np.maximum(readings - 0.5, 0.0))  # near face of cell z
    scans = Scans.one_d(ranges, max_range=F, position=0.5)
    return Toy1D(grid, scans, readings, int(wall), float(sigma))
