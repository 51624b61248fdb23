"""The studies of the amortised guides: ``amortised_guide_eval``, ``guide_limits`` and ``unseen_by_distance``
(:mod:`ogm_ppl.cli._studies`)."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from ogm_ppl.cli._studies import Study, StudyUsageError


# ------------------------------------------------------------------------------------- amortised_guide_eval
def _amortised_guide_eval_arguments(ap: argparse.ArgumentParser) -> None:
    from dataclasses import fields

    from ogm_ppl.studies.amortised_guide_eval import GuideEvalSettings

    d = GuideEvalSettings()
    for f in fields(GuideEvalSettings):  # one option per setting, with its default
        flag, default = "--" + f.name.replace("_", "-"), getattr(d, f.name)
        if f.name == "block":
            ap.add_argument(flag, type=int, nargs=2, default=default, help=f"{f.name} ({default})")
        else:
            ap.add_argument(flag, type=type(default), default=default, help=f"{f.name} ({default})")
    ap.add_argument("--out", default="out/amortised", help="the output folder (out/amortised)")


def _amortised_guide_eval_run(args: argparse.Namespace) -> int:
    from dataclasses import fields

    import torch

    from ogm_ppl.io import atomic_write_text
    from ogm_ppl.studies.amortised_guide_eval import GuideEvalSettings, GuideEvalSettingsError, guide_eval, markdown

    names = [f.name for f in fields(GuideEvalSettings)]
    try:
        settings = GuideEvalSettings(**{name: getattr(args, name) for name in names})
    except GuideEvalSettingsError as e:
        raise StudyUsageError(f"--{e.option.replace('_', '-')}: {e.reason}") from None
    torch.set_num_threads(1)
    r = guide_eval(settings)
    out = Path(args.out)
    options = {**{name: getattr(args, name) for name in names}, "out": args.out}
    record = {"settings": options, "trained_for": r.trained_for, "summary": r.summary, "per_map": r.per_map}
    atomic_write_text(out / "results.json", json.dumps({**record, "seconds": r.seconds}, indent=1) + "\n")
    md = markdown(r.summary, settings, r.trained_for)
    atomic_write_text(out / "results.md", md)
    print(md)
    print(f"{r.seconds:.0f} s; wrote {out}/results.json and results.md")
    return 0


AMORTISED_GUIDE_EVAL = Study(
    """The command line of :func:`ogm_ppl.studies.amortised_guide_eval.guide_eval` (the held-out maps, the reference
and the convergence measures are described in :mod:`ogm_ppl.studies.amortised_guide_eval`): the amortised guide
against Gibbs with the same prior and against p21 OGM. One option per setting. Writes OUT/results.json and
results.md and prints the table.

    ogm-ppl study amortised_guide_eval            # ~8 min on 2 cores; writes out/amortised/
    ogm-ppl study amortised_guide_eval --maps-a 1 --maps-b 1 --ref-sweeps 300 --chains 2 --sweeps 30""",
    _amortised_guide_eval_arguments,
    _amortised_guide_eval_run,
)


# --------------------------------------------------------------------------------------------- guide_limits
def _guide_limits_arguments(ap: argparse.ArgumentParser) -> None:
    from ogm_ppl.calibration import TEST_CORPORA

    ap.add_argument("--test", required=True, choices=TEST_CORPORA, help="the test corpus")
    ap.add_argument(
        "--guides",
        nargs="+",
        required=True,
        help="guide names, as ogm-ppl calibrate --guides takes; NAME=DIR reads that guide from DIR (e.g. one trained "
        "with other --channels), so several trainings of one guide can be compared",
    )
    ap.add_argument("--guide-dir", type=Path, default=None, help="read the guides as DIR/guide_CORPUS.npz")
    ap.add_argument("--plans", type=int, default=10, help="held-out maps of the test corpus (default 10)")
    ap.add_argument("--out", type=Path, default=Path("out/guide_limits"), help="the output folder (out/guide_limits)")


def _guide_limits_run(args: argparse.Namespace) -> dict:
    import torch

    from ogm_ppl.studies.guide_limits import guide_limits

    torch.set_num_threads(1)
    doc = guide_limits(
        args.test, args.guides, guide_dir=args.guide_dir, plans=args.plans, out=args.out,
        log=lambda line: print(line, flush=True),
    )  # fmt: skip
    for g, s in doc["summary"].items():
        print(f"{g}: " + ", ".join(f"{k} {v:.3f}" if isinstance(v, float) else f"{k} {v}" for k, v in s.items()))
    print(f"wrote {args.out / 'guide_limits.json'}")
    return doc


GUIDE_LIMITS = Study(
    """What limits a corpus guide's prediction of unseen cells: its calibration, or what it can tell apart? The
command line of :func:`ogm_ppl.studies.guide_limits.guide_limits` (what it reports is described there): per guide,
its NLL on the unseen cells of a test corpus's held-out maps, the oracle recalibrations' lower bounds and the
guides' ensemble, with per-map rows.

    ogm-ppl study guide_limits --test ipa --guides ipa houseexpo+ipa@sym   # ~2 min on 2 cores
    ogm-ppl study guide_limits --test houseexpo --guides houseexpo houseexpo+ipa@sym --guide-dir DIR
    ogm-ppl study guide_limits --test ipa --guides ipa ipa=out/capacity/c12 ipa=out/capacity/c48

Writes OUT/guide_limits.json (settings, provenance, per-map rows, summary).""",
    _guide_limits_arguments,
    _guide_limits_run,
)


# --------------------------------------------------------------------------------------- unseen_by_distance
def _unseen_by_distance_arguments(ap: argparse.ArgumentParser) -> None:
    from ogm_ppl.calibration import KERNELS
    from ogm_ppl.cli.calibrate import add_plan_file_arguments
    from ogm_ppl.studies.unseen_by_distance import TESTS

    what = ap.add_mutually_exclusive_group()
    what.add_argument(
        "--guide", default=None, help="a guide name ogm-ppl calibrate --guides takes (default houseexpo+ipa@sym)"
    )
    what.add_argument("--prior", default=None, help="a prior name (KIND[:CORPUS][@MOD]), sampled by chains")
    ap.add_argument("--guide-dir", type=Path, default=None, help="read the guide as DIR/guide_C.npz")
    ap.add_argument("--kernel", default="cycle", choices=sorted(KERNELS), help="a prior's sampler")
    ap.add_argument("--sweeps", type=int, nargs="+", default=[200], help="kept sweeps per chain (one run each)")
    ap.add_argument("--burn", type=int, default=None, help="warm-up sweeps per chain (default: a quarter of --sweeps)")
    ap.add_argument(
        "--test", nargs="+", default=None, choices=TESTS, help="test corpora (default: all, or none with --plan-files)"
    )
    add_plan_file_arguments(ap)
    ap.add_argument(
        "--plans", type=int, default=None, help="held-out maps per test corpus (default 10; every plan of --plan-files)"
    )
    ap.add_argument(
        "--out", type=Path, default=Path("out/unseen_by_distance"), help="the output folder (out/unseen_by_distance)"
    )


def _unseen_by_distance_run(args: argparse.Namespace) -> dict:
    from ogm_ppl.studies.unseen_by_distance import DistanceSettings, rows_table, unseen_by_distance

    opts = {k: getattr(args, k) for k in ("guide", "prior", "guide_dir", "kernel", "burn", "test", "plans")}
    files = {k: getattr(args, k) for k in ("plan_files", "plan_set", "pixel_size", "plan_outside")}
    settings = DistanceSettings(**opts, **files, sweeps=tuple(args.sweeps))
    doc = unseen_by_distance(settings, args.out, log=lambda line: print(line, flush=True))
    method = (
        f"{args.prior} ({args.kernel}, 3 chains)" if args.prior is not None else f"guide:{doc['settings']['guide']}"
    )
    print(rows_table(doc["rows"], method))
    print(f"wrote {args.out / 'unseen_by_distance.json'} ({doc['seconds']:.0f} s)")
    return doc


UNSEEN_BY_DISTANCE = Study(
    """Where a method's bits go on the unseen cells: NLL by distance to the nearest cell some ray reached. The
command line of :func:`ogm_ppl.studies.unseen_by_distance.unseen_by_distance` (the protocol and the bins are
described there): one method, an amortised guide (--guide, a name ``ogm-ppl calibrate --guides`` takes) or a prior
sampled by the calibration protocol's three chains (--prior; --kernel, --sweeps, --burn as ``ogm-ppl calibrate``
takes them, --sweeps one run per value), binned on the held-out maps of each test corpus.

    ogm-ppl study unseen_by_distance --guide houseexpo+ipa@sym --test houseexpo ipa   # about a minute
    ogm-ppl study unseen_by_distance --prior border_bo@cal --kernel cycle --test dungeon --plans 2 \\
        --sweeps 200 1000 3000
    ogm-ppl study unseen_by_distance --plan-files out/log_plans --plan-set logs --plan-outside unknown

--plan-files (and --plan-set, --pixel-size, --plan-outside, as ``ogm-ppl calibrate`` takes them) bins plans of
other buildings too; a prior run on them must name its corpus (KIND:CORPUS). Writes OUT/unseen_by_distance.json
(settings, provenance, one row per corpus, bin and sweep count) and prints a table.""",
    _unseen_by_distance_arguments,
    _unseen_by_distance_run,
)

STUDIES = {
    "amortised_guide_eval": AMORTISED_GUIDE_EVAL,
    "guide_limits": GUIDE_LIMITS,
    "unseen_by_distance": UNSEEN_BY_DISTANCE,
}
