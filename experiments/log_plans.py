r"""Floor plans of the real logs' buildings, cleaned from the maps of all their readings.

The maps are those ``experiments/map_all_logs.py`` builds from every reading of each log; the plans are what
``experiments/calibration.py --plan-files`` scores.

None of these buildings is in a training set (seven are in no floor-plan corpus; the IPA corpus's plans of Intel
and Freiburg 101 are left out of every training set, :data:`~ogm_ppl.datasets.floorplans.REAL_LOG_BUILDINGS`), so
they test the learned priors and guides on buildings nobody trained on. A map from a whole log is not yet a plan:
beams through glass, doors and gaps leave thin streaks of free cells far outside the building. Per log, with ``p``
the map's occupancy as ``map_server`` publishes it (``ogm-ppl map`` wrote it as ``<log>/ros/map.yaml``):

* occupied where ``p = 100``; free where ``p = 0`` *and* the cell lies in a ``k x k`` square of such cells
  (a morphological opening of the free cells, ``k = --min-free-cells``, default 9 cells = 45 cm, narrower than a
  door a robot drives through: the streaks go, rooms, doors and corridors stay) *and* in the largest connected
  component of those (the building the robot drove through; islands seen through windows go); every other cell
  unknown (the plan reader makes it occupied, as the corpora's exteriors are, or with
  ``calibration.py --plan-outside unknown`` leaves it unscored);
* written as ``<out>/<log>.yaml`` + ``.pgm`` (:func:`ogm_ppl.rosmap.save_ros_map`), 0.05 m a cell.

The outdoor log (``freiburg-campus``) is left out by default (``--exclude``).

    python experiments/map_all_logs.py --out out/logs          # 30-60 s: a map per log
    python experiments/log_plans.py --maps out/logs --out out/log_plans
    python experiments/calibration.py --plan-files out/log_plans --plan-set logs --plans 9 --plan-outside unknown \
        --priors independent --guides houseexpo+ipa@sym --out out/calibration_logs
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from ogm_ppl.rosmap import load_ros_map, save_ros_map

OUTDOOR = ("freiburg-campus",)
MIN_FREE_CELLS = 9


def clean(occupancy: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
    """``(probabilities, unknown)`` of a plan from a map_server occupancy array (``rows x cols``, 0..100, -1):
    occupied where 100, free where 0 inside a ``k x k`` square of free cells, unknown elsewhere."""
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


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument(
        "--maps", type=Path, default=Path("out/logs"), help="map_all_logs.py's output folder (default out/logs)"
    )
    ap.add_argument("--out", type=Path, default=Path("out/log_plans"), help="output folder (default out/log_plans)")
    ap.add_argument(
        "--min-free-cells",
        type=int,
        default=MIN_FREE_CELLS,
        help=f"side k of the opening square (default {MIN_FREE_CELLS})",
    )
    ap.add_argument("--exclude", nargs="*", default=list(OUTDOOR), help="logs left out (default the outdoor one)")
    args = ap.parse_args(argv)
    if args.min_free_cells < 1:
        ap.error("--min-free-cells must be at least 1")
    found = sorted(p for p in args.maps.glob("*/ros/map.yaml") if p.parent.parent.name not in args.exclude)
    if not found:
        ap.error(f"no <log>/ros/map.yaml under {args.maps}: run experiments/map_all_logs.py --out {args.maps}")
    for yaml_path in found:
        name = yaml_path.parent.parent.name
        m = load_ros_map(yaml_path)
        rows, cols = m.grid.shape
        p, unknown = clean(m.occupancy.reshape(rows, cols), args.min_free_cells)
        files = save_ros_map(args.out / f"{name}.yaml", p.ravel(), m.grid, unknown=unknown.ravel(), sidecar=False)
        print(
            f"{name}: {cols} x {rows} cells (W x H), {int((p == 1).sum()):,} occupied, "
            f"{int((~unknown & (p == 0)).sum()):,} "
            f"free -> {files.yaml}",
            flush=True,
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
