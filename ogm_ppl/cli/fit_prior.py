"""``ogm-ppl fit-prior tables|backoff|field|data-curve|deltas|delta-setting|temper|headline|bias|net-field``: fit
a learned prior's artefacts on a corpus or on plan files (and how their held-out score moves with the number of
plans), the update terms Delta of traditional OGM against exact 1D posteriors, what the calibration protocol
chooses on validation plans (tempering exponents, the headline's prior, biases), or a net field.

    ogm-ppl fit-prior tables --corpus ipa --out DIR             # prior_ipa.npz + .json (count tables)
    ogm-ppl fit-prior backoff --plan-files my_plans/ --pixel-size 0.025 --out DIR   # backoff_plans.json
    ogm-ppl fit-prior field --corpus dungeon --limit 20 --out DIR              # field_dungeon.npz + .json
    ogm-ppl fit-prior data-curve --corpus houseexpo-full --sizes 60 600 6000 --out DIR  # data_curve_houseexpo-full.json
    ogm-ppl fit-prior deltas --out DIR             # delta_<name>.json per term + delta_cv.json (the shipped fit)
    ogm-ppl fit-prior delta-setting --family p21 --sigma 1 --F 400 --out DIR   # one's own sensor (cells)
    ogm-ppl fit-prior temper --corpus ipa --out DIR            # temper_ipa.json (the @cal exponents)
    ogm-ppl fit-prior headline --out DIR                       # headline_prior.json (make run's prior)
    ogm-ppl fit-prior bias --priors border1_bo --train ipa --out DIR   # bias.json (calibrate --bias-file)
    ogm-ppl fit-prior net-field --corpus houseexpo --out DIR   # net_houseexpo.npz + .json (a net field)

A subcommand of :mod:`ogm_ppl.cli`: :func:`add_parser` adds it, :func:`run` runs it
(:func:`ogm_ppl.learn.fit_tables`, :func:`~ogm_ppl.learn.fit_backoff`, :func:`~ogm_ppl.learn.fit_field`,
:func:`~ogm_ppl.learn.fit_deltas`, :func:`~ogm_ppl.learn.fit_delta_setting`; the last four kinds:
:mod:`ogm_ppl.cli._fit_kinds`, :func:`~ogm_ppl.learn.fit_temper`, :func:`~ogm_ppl.learn.select_headline_prior`,
:func:`~ogm_ppl.learn.fit_bias`, :func:`~ogm_ppl.learn.fit_net_field`).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ogm_ppl.cli._fit_kinds import KINDS as PROTOCOL_KINDS
from ogm_ppl.cli._fit_kinds import sample_seed

NAME = "fit-prior"
PLAN_KINDS = ("tables", "backoff", "field")
KINDS = (*PLAN_KINDS, "data-curve", "deltas", "delta-setting", *PROTOCOL_KINDS)


def add_parser(sub: argparse._SubParsersAction) -> None:
    """Add ``fit-prior`` with one sub-subcommand per kind to the subcommands ``sub``."""
    from ogm_ppl.learn._fit_common import CORPORA
    from ogm_ppl.learn.field import FieldSettings

    p = sub.add_parser(
        NAME,
        help="fit a learned prior (count tables, back-off weights, pattern field, net field) on a corpus or your "
        "plans, the update terms Delta, or tempering exponents, the headline's prior and biases on validation plans",
        description=__doc__.splitlines()[0],
    )
    kinds = p.add_subparsers(
        dest="kind",
        metavar="{" + ",".join(KINDS) + "}",
        required=True,
        help="what to fit (KIND --help for its options)",
    )
    helps = {
        "tables": "count tables: relative frequencies of window configurations (prior_NAME.npz + .json)",
        "backoff": "Witten-Bell back-off weights on a fit/validation split (backoff_NAME.json)",
        "field": "pattern fields, one and two scales, by pseudo-likelihood and tempering (field_NAME.npz + .json)",
        "deltas": "update terms Delta of Table 2.1, pN and a network, cross-validated (delta_NAME.json, delta_cv.json)",
        "delta-setting": "update terms Delta for your sensor's noise and range in cells (delta_NAME_sigma..json)",
    }
    d = FieldSettings()
    for kind in PLAN_KINDS:
        k = kinds.add_parser(kind, help=helps[kind], description=helps[kind])
        src = k.add_mutually_exclusive_group(required=True)
        src.add_argument("--corpus", choices=CORPORA, help="fit on this corpus's training plans")
        src.add_argument("--plan-files", nargs="+", type=Path, metavar="PATH", help="plan files or folders of them")
        k.add_argument("--out", type=Path, required=True, help="the folder the fitted files go to")
        k.add_argument("--limit", type=int, default=None, help="the first N training plans (default: the corpus's)")
        k.add_argument("--sample", type=int, default=None, help="a random N of the corpus's training plans")
        k.add_argument("--sample-seed", type=int, default=None, help="the seed of --sample (0)")
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
    curve = "held-out score of the pattern field against the number of training plans (data_curve_CORPUS.json)"
    _add_data_curve(kinds.add_parser("data-curve", help=curve, description=curve), CORPORA)
    _add_deltas(kinds.add_parser("deltas", help=helps["deltas"], description=helps["deltas"]))
    _add_delta_setting(
        kinds.add_parser("delta-setting", help=helps["delta-setting"], description=helps["delta-setting"])
    )
    from ogm_ppl.cli._fit_kinds import add_kind

    for kind in PROTOCOL_KINDS:
        add_kind(kinds, kind)


def _add_data_curve(k: argparse.ArgumentParser, corpora) -> None:
    k.add_argument("--corpus", required=True, choices=[c for c in corpora if c != "generated"], help="the corpus")
    k.add_argument("--out", type=Path, required=True, help="the folder the file goes to")
    k.add_argument("--sizes", type=int, nargs="+", default=[60, 600, 6000], help="training plans per fit")
    k.add_argument("--validation", type=int, default=300, help="validation plans scored (300)")
    k.add_argument("--seed", type=int, default=0, help="the permutation's seed (0)")
    k.add_argument("--quiet", action="store_true", help="no progress output")


def _add_deltas(k: argparse.ArgumentParser) -> None:
    from ogm_ppl.learn.deltas import DATASETS, FAMILIES, FOLDS, SETTING

    k.add_argument("--out", type=Path, required=True, help="the folder the fitted files go to")
    k.add_argument("--datasets", type=int, default=DATASETS, help="training datasets (%(default)s)")
    k.add_argument("--folds", type=int, default=FOLDS, help="cross-validation folds, 0 for none (%(default)s)")
    k.add_argument("--families", nargs="+", default=list(FAMILIES), metavar="NAME", help="the terms (all)")
    k.add_argument("--seed", type=int, default=0, help="the datasets' seed (0)")
    k.add_argument("--sigma", type=float, default=SETTING["sigma"], help="sensor noise, cells (%(default)s)")
    k.add_argument("--F", type=int, default=SETTING["F"], help="sensor range, cells (%(default)s)")
    k.add_argument("--wall", type=int, default=SETTING["wall"], help="the wall's cell (%(default)s)")
    k.add_argument("--quiet", action="store_true", help="no progress output")


def _add_delta_setting(k: argparse.ArgumentParser) -> None:
    k.add_argument("--out", type=Path, required=True, help="the folder the fitted files go to")
    k.add_argument("--family", nargs="+", default=["p21"], metavar="NAME", help="pN, moravec_opt, ... (p21)")
    k.add_argument("--sigma", type=float, required=True, help="sensor noise in cells (sigma_m / resolution)")
    k.add_argument("--F", type=int, required=True, help="sensor range in cells (max_range_m / resolution)")
    k.add_argument("--wall", type=int, default=None, help="the wall's cell (round(0.8 F))")
    k.add_argument("--num", type=int, default=1000, help="training datasets (1000)")
    k.add_argument(
        "--num-readings", type=int, nargs=2, default=[1, 10], metavar=("LO", "HI"), help="readings per dataset (1 10)"
    )
    k.add_argument("--seed", type=int, default=0, help="the datasets' seed (0)")
    k.add_argument(
        "--prior", choices=("uniform", "data_driven"), default="uniform", help="the exact posteriors' prior (uniform)"
    )
    k.add_argument("--heldout", type=int, default=0, help="also score this many fresh datasets (0)")
    k.add_argument("--reuse", action="store_true", help="read a term of the same setting in --out, not refit")


def run(args: argparse.Namespace) -> int:
    """Run ``fit-prior``; prints the files written. Option errors raise :class:`~ogm_ppl.learn.FitOptionError`
    (a ``ValueError``: the command line reports it in one line naming the option and exits 2), its option
    spelled as the command line spells it (``check_size`` -> ``--check-size``) where it is one of the kind's."""
    from ogm_ppl.learn import FitOptionError

    try:
        return _run(args)
    except FitOptionError as e:
        flag = _flag(args, e.option)
        if flag is None:
            raise
        raise FitOptionError(flag, e.reason) from None


def _flag(args: argparse.Namespace, option: str) -> str | None:
    """``--OPTION`` (dashes for underscores, a trailing one dropped: ``lambda_`` -> ``--lambda``) where ``option``
    is an option of this command line (a destination of ``args``, or ``s_OPTION`` for the settings' fields)."""
    if not (hasattr(args, option) or hasattr(args, f"s_{option}")):
        return None
    return "--" + option.replace("_", "-").rstrip("-")


def _run(args: argparse.Namespace) -> int:
    from ogm_ppl.learn import FieldSettings, fit_backoff, fit_delta_setting, fit_deltas, fit_field, fit_tables

    if args.kind in PROTOCOL_KINDS:
        from ogm_ppl.cli._fit_kinds import run_kind

        return _done(args.kind, run_kind(args))
    if args.kind == "data-curve":
        from ogm_ppl.learn.data_curve import field_data_curve

        r = field_data_curve(
            args.corpus,
            args.out,
            sizes=args.sizes,
            validation=args.validation,
            seed=args.seed,
            progress=not args.quiet,
        )
        return _done(args.kind, r)
    if args.kind == "deltas":
        r = fit_deltas(
            args.out,
            datasets=args.datasets,
            folds=args.folds,
            families=args.families,
            seed=args.seed,
            sigma=args.sigma,
            F=args.F,
            wall=args.wall,
            progress=not args.quiet,
        )
        return _done(args.kind, r)
    if args.kind == "delta-setting":
        r = fit_delta_setting(
            args.out,
            family=args.family,
            sigma=args.sigma,
            F=args.F,
            wall=args.wall,
            num=args.num,
            num_readings=tuple(args.num_readings),
            seed=args.seed,
            prior=args.prior,
            heldout=args.heldout,
            reuse=args.reuse,
        )
        return _done(args.kind, r)
    from ogm_ppl.learn import load_training_plans

    source = args.corpus if args.corpus is not None else list(args.plan_files)
    seed = sample_seed(args)  # refused without --sample
    if args.sample is not None:
        source = load_training_plans(source, limit=args.limit, sample=args.sample, sample_seed=seed)
    common = dict(
        limit=None if args.sample is not None else args.limit,
        pixel_size=args.pixel_size,
        resolution=args.resolution,
        name=args.name,
    )
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
    return _done(args.kind, r)


def _done(kind: str, r) -> int:
    print(f"ogm-ppl fit-prior {kind}: {r.seconds:.1f} s -> " + ", ".join(str(f) for f in r.files), file=sys.stdout)
    return 0
