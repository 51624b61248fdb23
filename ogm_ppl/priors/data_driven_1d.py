r"""The 1D data-driven prior of Section 5.1: one wall, everything behind it occupied.

Along a ray of cells ``c_1..c_n`` (the cells a stationary robot's readings cross, in order), the maps with
non-zero prior are the ``n + 1`` maps ``0..0 1..1`` (a wall starting at any cell, or no wall), each with
probability ``1 / (n + 1)`` (Fig. 5.1). Cells off the ray, if any, must be free.
"""

from __future__ import annotations

import math

import torch

from ogm_ppl.priors.base import MapPrior

__all__ = ["DataDriven1DPrior"]


class DataDriven1DPrior(MapPrior):
    """The thesis's 1D "thick wall" prior over ``num_cells`` cells.

    Args:
        num_cells: K, cells of the grid.
        start: first cell of the ray (cells before it, e.g. the robot's own cell 0, are free).

    >>> p = DataDriven1DPrior(4, start=1)
    >>> p.log_prob(torch.tensor([[0., 0., 1., 1.], [0., 1., 0., 1.]])).exp().tolist()
    [0.25, 0.0]
    """

    #: maps that are not a wall from some cell onwards have zero mass
    can_be_zero = True

    def __init__(self, num_cells: int, start: int = 0) -> None:
        if not 0 <= start < num_cells:
            raise ValueError(f"DataDriven1DPrior.start must lie in 0..{num_cells - 1}, got {start}")
        self.num_cells = int(num_cells)
        self.start = int(start)
        self.n = self.num_cells - self.start  # cells that can hold the wall

    def __repr__(self) -> str:
        return f"DataDriven1DPrior(num_cells={self.num_cells}, start={self.start})"

    def log_prob(self, maps):
        maps = torch.as_tensor(maps, dtype=torch.float64)
        before = maps[..., : self.start].sum(-1) == 0
        ray = maps[..., self.start :]
        monotone = (ray[..., 1:] >= ray[..., :-1]).all(-1) if self.n > 1 else torch.ones_like(before)
        ok = before & monotone
        lp = torch.tensor(-math.log(self.n + 1), dtype=torch.float64)  # float64: a bare float gives float32
        return torch.where(ok, lp, torch.tensor(-math.inf, dtype=torch.float64))

    def sample(self, sample_shape=(), generator=None):
        shape = torch.Size(sample_shape)
        wall = torch.randint(0, self.n + 1, shape, generator=generator)  # n = no wall
        k = torch.arange(self.num_cells)
        return (k >= (wall[..., None] + self.start)).to(torch.float64)
