"""The 1D wall datasets of Section 2.5: a stationary robot, a wall at ``f = 60``, ``F = 75`` cells,
Gaussian readings with ``sigma = 3`` cells, and the exact posterior of each dataset.

Each dataset has a number of readings drawn uniformly from ``num_readings`` (the thesis does not state
it; our default is 1..10), each ``round(N(wall, sigma^2))`` clipped to ``[0, F]`` (a reading of ``F``
is a max-range reading). The robot sits in cell 0 (pinned free); cells ``1..F`` are latent. Readings are
summarised as counts per reading value (``z = 0..F`` and max range), which is all that traditional OGM
and the exact 1D posterior need. They are the training data of the Delta fit
(:mod:`~ogm_ppl.inference.variational.setting_fit`; they meet
:class:`~ogm_ppl.inference.variational.delta_fit.FitData`); :mod:`ogm_ppl.datasets` re-exports them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from ogm_ppl.grid import Grid
from ogm_ppl.inference.exact import pose_constrained_1d
from ogm_ppl.models.occupancy import OccupancyModel
from ogm_ppl.priors import DataDriven1DPrior, IndependentPrior
from ogm_ppl.raycast import raycast
from ogm_ppl.scans import Scans
from ogm_ppl.sensors import GaussianRange

__all__ = ["WallDatasets", "wall_datasets"]


@dataclass(frozen=True)
class WallDatasets:
    """``D`` datasets: ``counts`` (``D x (F + 2)``: readings per value ``z = 0..F`` and max range),
    ``exact`` (``D x (F + 1)`` exact marginals of cells ``0..F``), the readings and the settings."""

    readings: list
    counts: torch.Tensor
    exact: torch.Tensor
    F: int
    wall: int
    sigma: float
    prior: str
    seed: int

    def __len__(self) -> int:
        return self.counts.shape[0]

    def subset(self, idx) -> WallDatasets:
        idx = torch.as_tensor(idx, dtype=torch.long)
        return WallDatasets(
            [self.readings[i] for i in idx.tolist()],
            self.counts[idx],
            self.exact[idx],
            self.F,
            self.wall,
            self.sigma,
            self.prior,
            self.seed,
        )


def wall_datasets(
    num: int = 1000,
    F: int = 75,
    wall: int = 60,
    sigma: float = 3.0,
    num_readings: tuple[int, int] = (1, 10),
    prior: str = "uniform",
    seed: int = 0,
) -> WallDatasets:
    """Draw the datasets (seeded) and compute their exact posteriors (pose-constrained, Section 2.3.1).

    ``prior``: ``"uniform"`` (``lambda = 0.5``) or ``"data_driven"`` (Section 5.1).
    """
    if prior not in ("uniform", "data_driven"):
        raise ValueError(f"prior must be 'uniform' or 'data_driven', got {prior!r}")
    lo, hi = num_readings
    if not 1 <= lo <= hi:
        raise ValueError(f"num_readings must be (lo, hi) with 1 <= lo <= hi, got {num_readings}")
    rng = np.random.default_rng(seed)
    K = F + 1
    readings, counts, exact = [], torch.zeros(num, F + 2, dtype=torch.float64), torch.zeros(num, K, dtype=torch.float64)
    sensor = GaussianRange(sigma)
    grid = Grid.line(K)
    for d in range(num):
        n = int(rng.integers(lo, hi + 1))
        z = np.clip(np.rint(wall + sigma * rng.standard_normal(n)), 0, F)
        readings.append(z)
        # the robot at x = 1/2; a hit in cell z at its near face, a reading of F at max range
        scans = Scans.one_d(np.where(z >= F, F, np.maximum(z - 0.5, 0.0)), max_range=float(F), position=0.5)
        rays = raycast(grid, scans)
        p = IndependentPrior(0.5, K) if prior == "uniform" else DataDriven1DPrior(K, start=1)
        exact[d] = pose_constrained_1d(OccupancyModel(grid, rays, sensor, p)).marginals
        col = np.where(rays.is_max, F + 1, rays.z)
        counts[d] = torch.bincount(torch.from_numpy(col), minlength=F + 2).double()
    return WallDatasets(readings, counts, exact, F, wall, float(sigma), prior, seed)
