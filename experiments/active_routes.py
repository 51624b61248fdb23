r"""Where the rules of an ``active`` experiment send the robot: per-stop step lengths and coverage gains, and
the routes drawn on a plan.

    python experiments/active_routes.py out/active_medium                      # every method
    python experiments/active_routes.py out/active_medium --methods frontier patch3-ig patch3-cov-per-m \
        --plan p00 --levels 0.8 0.9

The command line of :func:`ogm_ppl.studies.active_routes.active_routes` (what is pooled, and how, is in
:mod:`ogm_ppl.studies.active_routes`): prints the table and writes ``route_stats.json`` and, with ``--plan``,
``routes_PLAN.png`` into the run's folder.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from ogm_ppl.studies.active_routes import active_routes, route_table
from ogm_ppl.studies.errors import STUDY_ERRORS


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("out", type=Path, help="the --out directory of an active experiment")
    ap.add_argument("--methods", nargs="+", default=None, help="these methods, in this order (default all)")
    ap.add_argument("--levels", nargs="+", type=float, default=[0.8, 0.9], help="coverage / F1 levels")
    ap.add_argument("--plan", default=None, help="draw the routes on this plan (e.g. p00)")
    ap.add_argument("--seed", type=int, default=0, help="the spec seed of the routes drawn")
    args = ap.parse_args(argv)
    try:
        rows = active_routes(args.out, args.methods, args.levels, args.plan, args.seed)
    except STUDY_ERRORS as e:
        raise SystemExit(f"active_routes.py: {e}") from None
    print(route_table(rows, args.levels))
    if args.plan:
        print(args.out / f"routes_{args.plan}.png")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
