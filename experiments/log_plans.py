r"""Floor plans of the real logs' buildings, cleaned from the maps of all their readings.

A thin front of :func:`ogm_ppl.studies.log_plans.log_plans` (the cleaning is described there): the maps are
those ``experiments/map_all_logs.py`` builds from every reading of each log, the plans are what
``experiments/calibration.py --plan-files`` scores. The outdoor log (``freiburg-campus``) is left out by default
(``--exclude``).

    python experiments/map_all_logs.py --out out/logs          # 30-60 s: a map per log
    python experiments/log_plans.py --maps out/logs --out out/log_plans
    python experiments/calibration.py --plan-files out/log_plans --plan-set logs --plans 9 --plan-outside unknown \
        --priors independent --guides houseexpo+ipa@sym --out out/calibration_logs
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from ogm_ppl.studies.log_plans import MIN_FREE_CELLS, OUTDOOR, LogPlanError, log_plans


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
    try:
        plans = log_plans(args.maps, args.out, min_free_cells=args.min_free_cells, exclude=args.exclude)
    except LogPlanError as e:
        ap.error(str(e))
    for p in plans:
        print(f"{p.name}: {p.cols} x {p.rows} cells (W x H), {p.occupied:,} occupied, {p.free:,} free -> {p.yaml}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
