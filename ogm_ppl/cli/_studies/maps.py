"""The studies of experiments' maps and of the real logs: ``table_6_4_errors``, ``touched_errors``,
``unobserved_marginals``, ``map_all_logs`` and ``log_plans`` (:mod:`ogm_ppl.cli._studies`)."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from ogm_ppl.cli._studies import Study, StudyUsageError


# ----------------------------------------------------------------------------------------- table_6_4_errors
def _table_6_4_errors_arguments(ap: argparse.ArgumentParser) -> None:
    ap.add_argument("out_dir", type=Path, help="an experiment's output folder (holding maps/ and datasets/)")
    ap.add_argument("--algorithms", nargs="+", help="only these (default: every map of the first dataset)")
    ap.add_argument("--json", type=Path, help="also write the result to this JSON file")


def _table_6_4_errors_run(args: argparse.Namespace) -> int:
    from ogm_ppl.io import atomic_write_text
    from ogm_ppl.studies.table_6_4_errors import error_split, error_split_text

    res = error_split(args.out_dir, algorithms=args.algorithms)
    print(error_split_text(res))
    if args.json:
        print("wrote", atomic_write_text(args.json, json.dumps(res, indent=1)))
    return 0


TABLE_6_4_ERRORS = Study(
    """Where the pooled errors of a Table 6.4 run lie: observed or never-observed cells, and the best F1 any map can
reach without predicting never-observed free space. The command line of
:func:`ogm_ppl.studies.table_6_4_errors.error_split` (the split and the two oracle maps are in
:mod:`ogm_ppl.studies.table_6_4_errors`): prints the summary, and with --json writes the result.

    ogm-ppl study table_6_4_errors out/experiments/table_6_4_full --json out/table_6_4_errors.json""",
    _table_6_4_errors_arguments,
    _table_6_4_errors_run,
)


# ------------------------------------------------------------------------------------------- touched_errors
def _touched_errors_arguments(ap: argparse.ArgumentParser) -> None:
    ap.add_argument("folder", type=Path, help="an experiment's output folder (ogm-ppl experiment --out)")
    ap.add_argument("algorithm", nargs="+", help="the algorithms (map names) to count")
    ap.add_argument("--datasets", nargs="+", default=None, help="default: every dataset of the folder")
    ap.add_argument("--out", type=Path, default=None, help="write touched_errors.json and .png here")


def _touched_errors_run(args: argparse.Namespace) -> dict:
    from ogm_ppl.studies.touched_errors import touched_errors

    result = touched_errors(args.folder, args.algorithm, datasets=args.datasets, out_dir=args.out)
    for d, algs in result["datasets"].items():
        for a, r in algs.items():
            print(d, a, json.dumps({k: r[k] for k in ("touched_best_f1", "false_negatives", "fp_binned")}))
    if args.out is not None:
        print(f"wrote {args.out / 'touched_errors.json'} and touched_errors.png")
    return result


TOUCHED_ERRORS = Study(
    """Where maps' errors on the touched cells of an experiment lie, against the benchmark's walls. The command line
of :func:`ogm_ppl.studies.touched_errors.touched_errors` (what is counted, and how, is in
:mod:`ogm_ppl.studies.touched_errors`): for each dataset and algorithm, at the algorithm's best touched-only
threshold, the walls missed by depth and the false positives by distance to the nearest benchmark wall.

--out DIR writes DIR/touched_errors.json (every count, the touched best F1 and threshold) and
DIR/touched_errors.png (one panel per dataset). Results page, Intel: "Where the touched cells differ".

    ogm-ppl study touched_errors out/experiments/intel_guide ogm guide-he-ipa --out out/touched
    ogm-ppl study touched_errors out/experiments/intel_6_5 ogm dd-L1 --datasets intel-pf1""",
    _touched_errors_arguments,
    _touched_errors_run,
)


# ------------------------------------------------------------------------------------- unobserved_marginals
def _unobserved_marginals_arguments(ap: argparse.ArgumentParser) -> None:
    ap.add_argument("out_dir", type=Path, help="an experiment's output folder (holding maps/)")
    ap.add_argument("--baseline", default="ogm", help="the traditional-OGM algorithm of the spec")
    ap.add_argument("--json", action="store_true", help="print JSON instead of a table")


def _unobserved_marginals_run(args: argparse.Namespace) -> int:
    from ogm_ppl.studies.unobserved_marginals import unobserved_means, unobserved_text

    res = unobserved_means(args.out_dir, args.baseline)
    print(json.dumps(res, indent=1) if args.json else unobserved_text(res))
    return 0


UNOBSERVED_MARGINALS = Study(
    """Mean marginal of the never-observed cells of each map an experiment wrote, per algorithm and dataset. The
command line of :func:`ogm_ppl.studies.unobserved_marginals.unobserved_means` (the cells and the mean are in
:mod:`ogm_ppl.studies.unobserved_marginals`): prints one line per algorithm, or the JSON with --json.

    ogm-ppl study unobserved_marginals out/experiments/table_6_4_tempered""",
    _unobserved_marginals_arguments,
    _unobserved_marginals_run,
)


# --------------------------------------------------------------------------------------------- map_all_logs
def _map_all_logs_arguments(ap: argparse.ArgumentParser) -> None:
    ap.add_argument("--out", type=Path, default=Path("out/logs"), help="output directory (default out/logs)")
    ap.add_argument("--only", help="comma-separated log names to map (default: all)")
    ap.add_argument(
        "--data", type=Path, default=Path("../shared/data"), help="the shared data folder (default ../shared/data)"
    )


def _map_all_logs_run(args: argparse.Namespace) -> int:
    from ogm_ppl.studies.map_all_logs import log_jobs, map_all_logs

    only = args.only.split(",") if args.only else None
    for name, cli_args in log_jobs(args.data).items():
        if only is None or name in only:
            print("ogm-ppl " + " ".join(["map", *cli_args, "--out", str(args.out / name)]), flush=True)
    text, failed = map_all_logs(args.out, args.data, only)
    print(text)
    return 1 if failed else 0


MAP_ALL_LOGS = Study(
    """Map every shipped CARMEN log with the ``ogm-ppl map`` command and summarise times and sizes. The command line
of :func:`ogm_ppl.studies.map_all_logs.map_all_logs` (the logs and their options are in
:mod:`ogm_ppl.studies.map_all_logs`), on the shared data folder (--data). Writes OUT/<name>/ (the files of
``ogm-ppl map``) and OUT/summary.md; the exit status is 1 when a log failed.

    ogm-ppl study map_all_logs [--out out/logs] [--only intel,seattle] [--data DIR]""",
    _map_all_logs_arguments,
    _map_all_logs_run,
)


# ------------------------------------------------------------------------------------------------ log_plans
def _log_plans_arguments(ap: argparse.ArgumentParser) -> None:
    from ogm_ppl.studies.log_plans import MIN_FREE_CELLS, OUTDOOR

    ap.add_argument(
        "--maps", type=Path, default=Path("out/logs"), help="map_all_logs's output folder (default out/logs)"
    )
    ap.add_argument("--out", type=Path, default=Path("out/log_plans"), help="output folder (default out/log_plans)")
    ap.add_argument(
        "--min-free-cells",
        type=int,
        default=MIN_FREE_CELLS,
        help=f"side k of the opening square (default {MIN_FREE_CELLS})",
    )
    ap.add_argument("--exclude", nargs="*", default=list(OUTDOOR), help="logs left out (default the outdoor one)")


def _log_plans_run(args: argparse.Namespace) -> int:
    from ogm_ppl.studies.log_plans import LogPlanError, log_plans

    if args.min_free_cells < 1:
        raise StudyUsageError("--min-free-cells must be at least 1")
    try:
        plans = log_plans(args.maps, args.out, min_free_cells=args.min_free_cells, exclude=args.exclude)
    except LogPlanError as e:
        raise StudyUsageError(str(e)) from None
    for p in plans:
        print(f"{p.name}: {p.cols} x {p.rows} cells (W x H), {p.occupied:,} occupied, {p.free:,} free -> {p.yaml}")
    return 0


LOG_PLANS = Study(
    """Floor plans of the real logs' buildings, cleaned from the maps of all their readings. The command line of
:func:`ogm_ppl.studies.log_plans.log_plans` (the cleaning is described there): the maps are those the study
``map_all_logs`` builds from every reading of each log, the plans are what ``ogm-ppl calibrate --plan-files``
scores. The outdoor log (freiburg-campus) is left out by default (--exclude).

    ogm-ppl study map_all_logs --out out/logs          # 30-60 s: a map per log
    ogm-ppl study log_plans --maps out/logs --out out/log_plans
    ogm-ppl calibrate --plan-files out/log_plans --plan-set logs --plans 9 --plan-outside unknown \\
        --priors independent --guides houseexpo+ipa@sym --out out/calibration_logs""",
    _log_plans_arguments,
    _log_plans_run,
)

STUDIES = {
    "table_6_4_errors": TABLE_6_4_ERRORS,
    "touched_errors": TOUCHED_ERRORS,
    "unobserved_marginals": UNOBSERVED_MARGINALS,
    "map_all_logs": MAP_ALL_LOGS,
    "log_plans": LOG_PLANS,
}
