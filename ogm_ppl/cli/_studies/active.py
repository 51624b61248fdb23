"""The studies of the ``active`` experiments: ``active_routes``, ``active_choice_probe`` and
``tune_distance_offset`` (:mod:`ogm_ppl.cli._studies`)."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from ogm_ppl.cli._studies import Study


# -------------------------------------------------------------------------------------------- active_routes
def _active_routes_arguments(ap: argparse.ArgumentParser) -> None:
    ap.add_argument("out", type=Path, help="the --out directory of an active experiment")
    ap.add_argument("--methods", nargs="+", default=None, help="these methods, in this order (default all)")
    ap.add_argument("--levels", nargs="+", type=float, default=[0.8, 0.9], help="coverage / F1 levels")
    ap.add_argument("--plan", default=None, help="draw the routes on this plan (e.g. p00)")
    ap.add_argument("--seed", type=int, default=0, help="the spec seed of the routes drawn")


def _active_routes_run(args: argparse.Namespace) -> int:
    from ogm_ppl.studies.active_routes import active_routes, route_table

    rows = active_routes(args.out, args.methods, args.levels, args.plan, args.seed)
    print(route_table(rows, args.levels))
    if args.plan:
        print(args.out / f"routes_{args.plan}.png")
    return 0


ACTIVE_ROUTES = Study(
    """Where the rules of an ``active`` experiment send the robot: per-stop step lengths and coverage gains, and the
routes drawn on a plan. The command line of :func:`ogm_ppl.studies.active_routes.active_routes` (what is pooled,
and how, is in :mod:`ogm_ppl.studies.active_routes`): prints the table and writes route_stats.json and, with
--plan, routes_PLAN.png into the run's folder.

    ogm-ppl study active_routes out/active_medium                      # every method
    ogm-ppl study active_routes out/active_medium --methods frontier patch3-ig patch3-cov-per-m \\
        --plan p00 --levels 0.8 0.9""",
    _active_routes_arguments,
    _active_routes_run,
)


# -------------------------------------------------------------------------------------- active_choice_probe
def _active_choice_probe_arguments(ap: argparse.ArgumentParser) -> None:
    ap.add_argument("out", type=Path, help="the --out directory of an active experiment")
    ap.add_argument("--method", default="patch3-ig", help="a sample_info method of the run's spec")
    ap.add_argument("--seed", type=int, default=0, help="the spec seed (default 0)")


def _active_choice_probe_run(args: argparse.Namespace) -> int:
    from ogm_ppl.studies.active_choice_probe import active_choice_probe

    res = active_choice_probe(args.out, args.method, args.seed)
    for pid, same in res["reruns"].items():
        n = sum(r["plan"] == pid for r in res["stops"])
        print(f"{pid}: {n} stops probed; rerun matches the task's path to 90 % coverage: {same}")
    print(json.dumps(res["summary"], indent=1))
    return 0


ACTIVE_CHOICE_PROBE = Study(
    """What the information-gain rule trades away: at every stop of a sample_info run, the candidates' information
gain beside their expected newly observed cells, both over the same posterior samples. The command line of
:func:`ogm_ppl.studies.active_choice_probe.active_choice_probe` (the scores and the pooled summary are in
:mod:`ogm_ppl.studies.active_choice_probe`): prints, per plan, the stops probed and whether the rerun matches the
task, then the summary, and writes OUT/choice_probe_METHOD.json.

    ogm-ppl study active_choice_probe out/active_medium --method patch3-ig --seed 0""",
    _active_choice_probe_arguments,
    _active_choice_probe_run,
)


# ------------------------------------------------------------------------------------- tune_distance_offset
def _tune_distance_offset_arguments(ap: argparse.ArgumentParser) -> None:
    ap.add_argument("spec", type=Path, help="an active spec (robot, stops, corpus, window and the methods)")
    ap.add_argument("--methods", nargs="+", required=True, help="per-metre methods of the spec to tune")
    ap.add_argument("--offsets", nargs="+", type=float, default=[0.5, 1.0, 2.0, 4.0], help="d_0 values (m)")
    ap.add_argument("--plans", type=int, default=8, help="validation plans (default 8)")
    ap.add_argument("--out", type=Path, default=Path("out/tune_distance_offset.json"), help="the JSON written")


def _tune_distance_offset_run(args: argparse.Namespace) -> int:
    from ogm_ppl.io import atomic_write_text
    from ogm_ppl.studies.tune_distance_offset import tune_distance_offset

    doc = tune_distance_offset(args.spec, args.methods, args.offsets, args.plans)
    for name, d0 in doc["chosen"].items():
        print(f"{name}: chosen d0 = {d0:g} m")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_text(args.out, json.dumps(doc, indent=1, allow_nan=True))
    print(args.out)
    return 0


TUNE_DISTANCE_OFFSET = Study(
    """Choose the distance offset d_0 of the per-metre exploration rules on *validation* plans, never on the
held-out plans the ``active`` experiments score. The command line of
:func:`ogm_ppl.studies.tune_distance_offset.tune_distance_offset` (the protocol and the criterion are in
:mod:`ogm_ppl.studies.tune_distance_offset`). Writes --out (JSON): every run's path to 90 % coverage and to F1
0.9, the per-offset summary and the chosen offset per method, with the validation plans used.

    ogm-ppl study tune_distance_offset experiments/specs/active_medium.toml \\
        --methods patch3-cov-per-m indep-cov-per-m --offsets 0.5 1 2 4 --plans 8 --out out/tune_d0.json""",
    _tune_distance_offset_arguments,
    _tune_distance_offset_run,
)

STUDIES = {
    "active_routes": ACTIVE_ROUTES,
    "active_choice_probe": ACTIVE_CHOICE_PROBE,
    "tune_distance_offset": TUNE_DISTANCE_OFFSET,
}
