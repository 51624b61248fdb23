"""The scene of a test map (thesis Section 5.2.1): its simulated sparse scan and the cells scored.

A test map (:class:`~ogm_ppl.calibration.heldout.TestMap`, ``H x W``, ``K = H W`` cells) is scanned by a
stop-and-scan route (:func:`~ogm_ppl.datasets.stop_and_scan.stop_and_scan`: ``poses`` stops, ``beams`` beams
per 360-degree scan, ranges up to ``range_cells`` with Gaussian noise ``sigma`` cells), and the rays cast on
its grid. Two masks are scored: the near-mapped cells ``N`` (within 10 cells of a cell some ray reached,
Fig. 6.16b) and its *unseen* cells ``U`` (cells of ``N`` no ray reached). :func:`score_marginals` scores
marginals ``q_k = p(m_k = 1 | z)`` on both.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol

import numpy as np

from ogm_ppl.calibration.heldout import TestMap, plan_file_maps
from ogm_ppl.datasets.stop_and_scan import stop_and_scan
from ogm_ppl.grid import Grid
from ogm_ppl.metrics import near_mapped_mask, prediction_scores, reliability
from ogm_ppl.raycast import Rays, raycast

__all__ = [
    "MASKS",
    "NEAR_CELLS",
    "PlanSetOptions",
    "CalibrationScene",
    "SceneOptions",
    "make_scene",
    "plan_set_maps",
    "score_marginals",
]

#: the scored masks: the unseen cells ``U`` and the near-mapped cells ``N`` they lie in
MASKS: tuple[str, ...] = ("unseen", "near")
#: the near-mapped mask's reach: cells within this many cells of a reached cell
NEAR_CELLS = 10.0


class SceneOptions(Protocol):
    """The sensor of a scene (:class:`~ogm_ppl.calibration.settings.CalibrationSettings` has these, and so
    does any object with the same attributes)."""

    @property
    def poses(self) -> int: ...
    @property
    def beams(self) -> int: ...
    @property
    def range_cells(self) -> float: ...
    @property
    def sigma(self) -> float: ...
    @property
    def seed(self) -> int: ...


class PlanSetOptions(Protocol):
    """The plan files of a test set and how they are read (:func:`plan_set_maps`)."""

    @property
    def plan_files(self) -> Sequence[Path] | None: ...
    @property
    def window(self) -> int: ...
    @property
    def pixel_size(self) -> float | None: ...
    @property
    def plan_set(self) -> str: ...
    @property
    def plan_outside(self) -> str: ...


@dataclass
class CalibrationScene:
    """A test map scanned: ``tmap``, its ``grid`` and cast ``rays``, and ``masks`` (``"near"``, ``"unseen"``:
    ``(K,)`` bool each, row-major over the grid)."""

    tmap: TestMap
    grid: Grid
    rays: Rays
    masks: dict[str, np.ndarray]


def make_scene(t: TestMap, options: SceneOptions) -> CalibrationScene:
    """The sparse dataset of a test map and its scored masks. Cells the map does not know (``~t.known``) are
    walls to the simulated sensor and are never scored (the corpora's maps know every cell)."""
    grid = Grid(t.truth.shape, resolution=t.resolution)
    data = stop_and_scan(
        t.truth | ~t.known,
        grid,
        num_poses=options.poses,
        beams=options.beams,
        max_range_cells=options.range_cells,
        sigma_cells=options.sigma,
        seed=options.seed,
    )
    rays = raycast(grid, data.scans)
    reached = rays.reached().reshape(grid.shape)
    near = near_mapped_mask(reached, NEAR_CELLS) & t.known
    unseen = near & ~reached
    return CalibrationScene(t, grid, rays, {"near": near.ravel(), "unseen": unseen.ravel()})


def score_marginals(scene: CalibrationScene, q: np.ndarray, unknown: np.ndarray | None = None) -> dict[str, dict]:
    """The scores of marginals ``q`` (``(K,)``, ``q_k = p(m_k = 1 | z)``) against the scene's truth on each
    mask of :data:`MASKS`: :func:`~ogm_ppl.metrics.prediction_scores` (NLL in bits per cell
    ``-1/|M| sum_k log2 q_k^{m_k} (1 - q_k)^{1 - m_k}``, ECE, Brier, ROC AUC, best F1, IoU; ``unknown`` cells
    counted free for the thresholded scores) and the reliability diagram (10 equal-width bins) as a dict."""
    truth = scene.tmap.truth.ravel()
    out = {}
    for mask_name in MASKS:
        mask = scene.masks[mask_name]
        s: dict = dict(prediction_scores(q, truth, mask=mask, unknown=unknown))
        s["reliability"] = reliability(q, truth, mask=mask).to_dict()
        out[mask_name] = s
    return out


def plan_set_maps(options: PlanSetOptions, n: int | None) -> list[TestMap]:
    """The first ``n`` usable maps of the plan files' test set (``None``: all of them;
    :func:`~ogm_ppl.calibration.heldout.plan_file_maps` with the options' files, window, pixel size, label and
    reading of unknown cells)."""
    if not options.plan_files:
        raise ValueError("plan_set_maps: no plan files given")
    return plan_file_maps(
        list(options.plan_files), n, options.window, options.pixel_size, options.plan_set, options.plan_outside
    )
