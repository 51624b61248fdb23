r"""What a map method is given and what it returns.

* :class:`MapProblem` — the data: a grid, the scans, the sensor's range noise in cells if known. It traces
  the rays once (:attr:`MapProblem.rays`, timed) and builds the occupancy model
  ``p(m) prod_n p(z_n | f_n(m))`` (Eq. 2.6) of a prior and a sensor, each by name (:meth:`MapProblem.model`).
* :class:`RunContext` — how to run: seed, chain, folders for checkpoints and caches, resume, a stop after
  some sweeps, progress, and a scoring function for the records of running marginals.
* :class:`MapResult` — ``K`` occupancy probabilities, the observed mask, timings and JSON-able details.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ogm_ppl.progress import Progress

if TYPE_CHECKING:
    from ogm_ppl.grid import Grid
    from ogm_ppl.models.occupancy import OccupancyModel
    from ogm_ppl.raycast import Rays
    from ogm_ppl.scans import Scans
    from ogm_ppl.sensors import SensorModel

__all__ = ["DEFAULT_SIGMA_CELLS", "MapProblem", "MapResult", "RunContext"]

#: range noise of the models in cells when neither the method nor the data gives one (about the scatter of
#: a corrected real log at 5 cm)
DEFAULT_SIGMA_CELLS = 1.0


@dataclass
class MapProblem:
    """The data a method maps.

    Args:
        grid: the map's grid (``K`` cells).
        scans: the readings.
        sigma_cells: the data's range noise in cells (a simulation's, a spec's), ``None`` if unknown.
    """

    grid: Grid
    scans: Scans
    sigma_cells: float | None = None
    ray_cast_seconds: float | None = field(default=None, init=False)
    _rays: Rays | None = field(default=None, init=False, repr=False)

    @property
    def rays(self) -> Rays:
        """The beams' traversals (:func:`~ogm_ppl.raycast.raycast`), traced on first use; a cast that would not
        fit in the free memory is refused before it runs (``MemoryError`` stating the estimate)."""
        if self._rays is None:
            from ogm_ppl.models.occupancy import check_ray_cast_memory
            from ogm_ppl.raycast import raycast

            check_ray_cast_memory(self.grid, self.scans)  # before the cast: its buffers, estimated
            t0 = time.perf_counter()
            self._rays = raycast(self.grid, self.scans)
            self.ray_cast_seconds = time.perf_counter() - t0
        return self._rays

    def sigma(self, override: float | None = None) -> float:
        """The range noise in cells: ``override``, else the data's, else :data:`DEFAULT_SIGMA_CELLS`."""
        if override is not None:
            return float(override)
        return float(self.sigma_cells) if self.sigma_cells else DEFAULT_SIGMA_CELLS

    @property
    def max_range_cells(self) -> int:
        """The sensor's maximum range in cells, ``round(max range / resolution)``."""
        return round(float(np.max(self.scans.max_range)) / self.grid.resolution)

    def prior(self, name: str, lam: float | None = None):
        """The prior ``name`` (:func:`~ogm_ppl.priors.named.prior_by_name`) over the grid (which warns when the
        grid's cells differ in size from those the prior was learned at); ``name = "independent"`` with ``lam``:
        every cell occupied with probability ``lam``."""
        from ogm_ppl.priors import IndependentPrior, prior_by_name

        if name == "independent" and lam is not None:
            return IndependentPrior(float(lam), self.grid.num_cells)
        return prior_by_name(name, self.grid)

    def sensor(self, name: str = "gaussian", sigma_cells: float | None = None, p_rand: float = 0.0) -> SensorModel:
        """The sensor ``name`` (:func:`~ogm_ppl.sensors.sensor_by_name`) for the range noise
        :meth:`sigma` ``(sigma_cells)`` and a share ``p_rand`` of random readings; ``"gaussian"`` is
        ``GaussianRange(sigma(sigma_cells), p_rand)``."""
        from ogm_ppl.sensors import sensor_by_name

        return sensor_by_name(name, self.sigma(sigma_cells), p_rand)

    def model(
        self,
        prior: str = "independent",
        lam: float | None = None,
        sigma_cells: float | None = None,
        p_rand: float = 0.0,
        sensor: str = "gaussian",
    ) -> OccupancyModel:
        """The occupancy model of :meth:`prior` ``(prior, lam)`` and :meth:`sensor` ``(sensor, sigma_cells,
        p_rand)``."""
        from ogm_ppl.models.occupancy import OccupancyModel, check_ray_cast_memory

        if self._rays is None:  # the cast and the model together, before the cast
            check_ray_cast_memory(self.grid, self.scans, model=True)
        return OccupancyModel(self.grid, self.rays, self.sensor(sensor, sigma_cells, p_rand), self.prior(prior, lam))


@dataclass
class RunContext:
    """How a method runs.

    Args:
        seed: seeds the run (chain ``c`` of an experiment gets its own).
        checkpoint_dir: where a sampling method keeps its checkpoint (``gibbs.npz``) and its records
            (``trace.json``); ``None``: no checkpoints.
        cache_dir: where results worth keeping between runs go (update terms fitted for a setting).
        resume: continue from the checkpoint if there is one.
        stop_after: stop a sampling run after this many sweeps of this call (its checkpoint kept, no map).
        progress: show progress (:class:`~ogm_ppl.progress.Progress`: a bar on a terminal, plain lines
            elsewhere once a run has taken 10 s).
        score: scores of running marginals (``K`` floats -> dict), recorded by sampling methods.
        where: names the run in warnings (``"experiment dataset office"``).
        label: names the run in its progress lines (``"office/gibbs/c0"``); a labelled run prints plain
            lines, never a bar, since it runs beside others (an experiment's tasks on dask workers).
    """

    seed: int = 0
    checkpoint_dir: Path | None = None
    cache_dir: Path | None = None
    resume: bool = True
    stop_after: int | None = None
    progress: bool = False
    score: Callable[[np.ndarray], dict] | None = None
    where: str = ""
    label: str = ""

    def progress_for(self, total: int, what: str, unit: str, initial: int = 0) -> Progress:
        """The run's :class:`~ogm_ppl.progress.Progress` over ``total`` ``unit`` (``what``: e.g. ``"gibbs
        sweeps"``, prefixed by :attr:`label`; plain lines once past 10 s, as the class says)."""
        desc = f"{self.label}: {what}" if self.label else what
        bar = False if self.label else None
        return Progress(total, desc, unit=unit, enabled=self.progress, after=10.0, bar=bar, initial=initial)


@dataclass
class MapResult:
    """What a method returns.

    Attributes:
        probabilities: ``K`` float64 occupancy probabilities; ``None`` when a sampling run stopped early
            (``stop_after``) and left its checkpoint.
        observed: ``K`` bool, the cells some beam reached.
        seconds: ``{"ray_cast": s or None (fused with the update), "map": s}``, set by the registry.
        details: JSON-able facts about the run (kernel, fitted term, records, warnings, ...).
    """

    probabilities: np.ndarray | None
    observed: np.ndarray
    details: dict[str, Any] = field(default_factory=dict)
    seconds: dict[str, float | None] = field(default_factory=dict)

    @property
    def complete(self) -> bool:
        return self.probabilities is not None
