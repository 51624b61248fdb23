r"""Floor plans of real logs' buildings, cleaned from the maps of all their readings.

A map built from every reading of a log (``ogm-ppl map`` writes it as ``<log>/ros/map.yaml``) is not yet a
plan: beams through glass, doors and gaps leave thin streaks of free cells far outside the building, and rooms
seen through windows leave free islands. :func:`log_plans` turns such maps into plans that
``ogm-ppl calibrate --plan-files`` scores (thesis Section 5.2.1's protocol on buildings in no corpus). Per log,
with ``p`` the map's occupancy as ``map_server`` publishes it (0..100, -1 unknown), :func:`clean` keeps:

* occupied: the cells where ``p = 100``;
* free: the cells where ``p = 0`` that lie in a ``k x k`` square of such cells (the morphological opening of
  the free cells by a ``k x k`` square; ``k = 9`` cells = 45 cm at 5 cm cells, narrower than a door a robot
  drives through: the streaks go, rooms, doors and corridors stay) *and* in the largest 4-connected component
  of those (the building the robot drove through: islands go);
* unknown: every other cell (a plan reader makes it occupied, as the corpora's exteriors are, or with
  ``plan_outside="unknown"`` leaves it unscored).

Each plan is written as ``<out>/<log>.yaml`` + ``.pgm`` (:func:`ogm_ppl.rosmap.save_ros_map`) on the map's
own grid. The outdoor log (``freiburg-campus``, :data:`OUTDOOR`) is left out by default.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ogm_ppl.rosmap import load_ros_map, save_ros_map

__all__ = ["MIN_FREE_CELLS", "OUTDOOR", "LogPlan", "LogPlanError", "clean", "log_plans"]

#: the logs left out by default: outdoors, no building to score
OUTDOOR: tuple[str, ...] = ("freiburg-campus",)
#: the default side ``k`` of the opening square, in cells
MIN_FREE_CELLS = 9


class LogPlanError(ValueError):
    """A setting of :func:`log_plans` out of range, or no log map to clean; the message says which."""


@dataclass(frozen=True)
class LogPlan:
    """One cleaned plan: the log's ``name``, the map's ``cols x rows`` cells, the ``occupied`` and ``free``
    cells kept, and the ``yaml`` file written (its image beside it)."""

    name: str
    cols: int
    rows: int
    occupied: int
    free: int
    yaml: Path


def clean(occupancy: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
    """``(probabilities, unknown)`` of a plan from a ``map_server`` occupancy array (``rows x cols`` of 0..100
    and -1): ``probabilities`` is 1.0 where ``occupancy >= 50`` and 0.0 elsewhere; ``unknown`` (bool, same
    shape) is true except on those occupied cells and on the free cells (``0 <= occupancy < 50``) that lie in a
    ``k x k`` square of free cells and in the largest connected component of such cells (``k = 1``: no
    opening, the largest component only)."""
    from scipy import ndimage

    occ = occupancy >= 50
    free = (occupancy >= 0) & ~occ
    if k > 1:
        free = ndimage.binary_opening(free, structure=np.ones((k, k), dtype=bool))
    labels, n = ndimage.label(free)
    if n > 1:
        free = labels == 1 + int(np.argmax(np.bincount(labels.ravel())[1:]))
    unknown = ~(occ | free)
    return np.where(occ, 1.0, 0.0), unknown


def log_maps(maps: str | os.PathLike, exclude: Sequence[str] = OUTDOOR) -> list[Path]:
    """The ``<log>/ros/map.yaml`` files under ``maps`` (sorted; the logs named in ``exclude`` left out)."""
    return sorted(p for p in Path(maps).glob("*/ros/map.yaml") if p.parent.parent.name not in exclude)


def log_plans(
    maps: str | os.PathLike,
    out: str | os.PathLike,
    *,
    min_free_cells: int = MIN_FREE_CELLS,
    exclude: Sequence[str] = OUTDOOR,
) -> list[LogPlan]:
    """Clean every log map under ``maps`` (``<log>/ros/map.yaml``, as ``ogm-ppl map`` writes it) into a plan
    (:func:`clean` with ``k = min_free_cells``) and write it into ``out`` as ``<log>.yaml`` + ``.pgm``; the
    logs named in ``exclude`` are left out. Returns one :class:`LogPlan` per log, in name order.

    Raises:
        LogPlanError: ``min_free_cells`` below 1, or no log map under ``maps``.
    """
    if min_free_cells < 1:
        raise LogPlanError(f"min_free_cells must be at least 1, got {min_free_cells}")
    found = log_maps(maps, exclude)
    if not found:
        raise LogPlanError(
            f"no <log>/ros/map.yaml under {maps}: map each log first (ogm-ppl map LOG --out {maps}/<log>)"
        )
    out = Path(out)
    plans = []
    for yaml_path in found:
        name = yaml_path.parent.parent.name
        m = load_ros_map(yaml_path)
        rows, cols = m.grid.shape
        p, unknown = clean(m.occupancy.reshape(rows, cols), min_free_cells)
        files = save_ros_map(out / f"{name}.yaml", p.ravel(), m.grid, unknown=unknown.ravel(), sidecar=False)
        occupied, free = int((p == 1).sum()), int((~unknown & (p == 0)).sum())
        plans.append(LogPlan(name, cols, rows, occupied, free, Path(files.yaml)))
    return plans
