"""``ogm-ppl fit-prior tables|backoff|field``: fit a learned prior's artefacts on a corpus or on plan files.

    ogm-ppl fit-prior tables --corpus ipa --out DIR             # prior_ipa.npz + .json (count tables)
    ogm-ppl fit-prior backoff --plans my_plans/ --pixel-size 0.025 --out DIR   # backoff_plans.json
    ogm-ppl fit-prior field --corpus dungeon --limit 20 --out DIR              # field_dungeon.npz + .json

A command module of the ``ogm-ppl`` command line: :func:`add_parser` adds the subcommand, :func:`run` runs
it (:func:`ogm_ppl.learn.fit_tables`, :func:`~ogm_ppl.learn.fit_backoff`, :func:`~ogm_ppl.learn.fit_field`).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

NAME = "fit-prior"
KINDS = ("tables", "backoff", "field")


def add_parser(sub: argparse._SubParsersAction) -> None:
    """Add ``fit-prior`` with one sub-subcommand per kind to the subcommands ``sub``."""
    from ogm_ppl.learn._fit_common import CORPORA
    from ogm_ppl.learn.field import FieldSettings

    p = sub.add_parser(
        NAME,
        help="fit a learned prior (count tables, back-off weights, pattern field) on a corpus or your plans",
        description=__doc__.splitlines()[0],
    )
    kinds = p.add_subparsers(dest="kind", metavar="{" + ",".join(KINDS) + "}", required=True)
    helps = {
        "tables": "count tables: relative frequencies of window configurations (prior_NAME.npz + .json)",
        "backoff": "Witten-Bell back-off weights on a fit/validation split (backoff_NAME.json)",
        "field": "pattern fields, one and two scales, by pseudo-likelihood and tempering (field_NAME.npz + .json)",
    }
    d = FieldSettings()
    for kind in KINDS:
        k = kinds.add_parser(kind, help=helps[kind], description=helps[kind])
        src = k.add_mutually_exclusive_group(required=True)
        src.add_argument("--corpus", choices=CORPORA, help="fit on this corpus's training plans")
        src.add_argument("--plans", nargs="+", type=Path, metavar="PATH", help="plan files or folders of them")
        k.add_argument("--out", type=Path, required=True, help="the folder the fitted files go to")
        k.add_argument("--limit", type=int, default=None, help="the first N training plans (default: the corpus's)")
        k.add_argument("--pixel-size", type=float, default=None, help="metres per pixel of plan images")
        k.add_argument("--resolution", type=float, default=0.05, help="metres per cell of plan files (0.05)")
        k.add_argument("--name", default=None, help="the files' name part (default the corpus, or 'plans')")
        k.add_argument("--quiet", action="store_true", help="no progress output")
        if kind == "tables":
            k.add_argument("--min-count-5x5", type=int, default=2, help="drop 5 x 5 codes seen fewer times (2)")
        else:
            k.add_argument(
                "--validation-every",
                type=int,
                default=5 if kind == "backoff" else 10,
                help="every N-th plan is validation (%(default)s)",
            )
        if kind == "field":
            k.add_argument("--betas", type=float, nargs="+", default=list(d.betas), help="powers beta tried")
            k.add_argument("--check-size", type=int, default=d.check_size, help="grid side of each power's chains")
            k.add_argument("--check-chains", type=int, default=d.check_chains, help="chains per start and power")
            k.add_argument("--check-sweeps", type=int, default=d.check_sweeps, help="sweeps per chain and power")
            k.add_argument("--pl-max-iter", type=int, default=d.pl_max_iter, help="LBFGS iterations per PL fit")
            k.add_argument("--bias-steps", type=int, default=d.bias_steps, help="bisection steps of the bias")
            k.add_argument("--report-sizes", type=int, nargs="+", default=list(d.report_sizes), help="check grids")
            k.add_argument("--report-sweeps", type=int, default=d.report_sweeps, help="sweeps of the final check")
            k.add_argument("--seed", type=int, default=d.seed, help="seed of every sampler (0)")
            k.add_argument("--no-resume", action="store_true", help="ignore a checkpoint in --out, start afresh")


def run(args: argparse.Namespace) -> int:
    """Run ``fit-prior``; prints the files written. Option errors raise :class:`~ogm_ppl.learn.FitOptionError`
    (a ``ValueError``: the command line reports it as an error and exits 2)."""
    from ogm_ppl.learn import FieldSettings, fit_backoff, fit_field, fit_tables

    source = args.corpus if args.corpus is not None else list(args.plans)
    common = dict(limit=args.limit, pixel_size=args.pixel_size, resolution=args.resolution, name=args.name)
    if args.kind == "tables":
        r = fit_tables(source, args.out, min_count_5x5=args.min_count_5x5, progress=not args.quiet, **common)
    elif args.kind == "backoff":
        r = fit_backoff(source, args.out, validation_every=args.validation_every, progress=not args.quiet, **common)
    else:
        settings = FieldSettings(
            betas=tuple(args.betas),
            check_size=args.check_size,
            check_chains=args.check_chains,
            check_sweeps=args.check_sweeps,
            pl_max_iter=args.pl_max_iter,
            bias_steps=args.bias_steps,
            report_sizes=tuple(args.report_sizes),
            report_sweeps=args.report_sweeps,
            seed=args.seed,
        )
        r = fit_field(
            source,
            args.out,
            settings=settings,
            validation_every=args.validation_every,
            resume=not args.no_resume,
            progress=not args.quiet,
            **common,
        )
    print(f"ogm-ppl fit-prior {args.kind}: {r.seconds:.1f} s -> " + ", ".join(str(f) for f in r.files), file=sys.stdout)
    return 0


def main(argv: list[str] | None = None) -> int:
    """``fit-prior`` alone (until the command line registers it): parse ``argv`` and :func:`run`."""
    parser = argparse.ArgumentParser(prog="ogm-ppl")
    add_parser(parser.add_subparsers(dest="command", required=True))
    return run(parser.parse_args(argv))
