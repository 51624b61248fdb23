"""The kinds of ``ogm-ppl fit-prior`` scored on validation plans: by the calibration protocol ``temper``
(:func:`ogm_ppl.learn.fit_temper`), ``headline`` (:func:`~ogm_ppl.learn.select_headline_prior`) and ``bias``
(:func:`~ogm_ppl.learn.fit_bias`), and by the held-out conditionals ``net-field``
(:func:`~ogm_ppl.learn.fit_net_field`): each one's options (``add_KIND``) and run (``run_KIND``).

    ogm-ppl fit-prior temper --corpus dungeon --out DIR       # temper_dungeon.json (the @cal exponents)
    ogm-ppl fit-prior headline --out DIR                      # headline_prior.json (the headline's prior)
    ogm-ppl fit-prior bias --priors border1_bo --train ipa --out DIR   # bias.json (calibrate --bias-file)
    ogm-ppl fit-prior net-field --corpus houseexpo --out DIR  # net_houseexpo.npz + .json (a net field)
"""

from __future__ import annotations

import argparse
from collections.abc import Callable
from pathlib import Path
from typing import Any

__all__ = ["HELPS", "KINDS", "add_headline", "add_kind", "add_temper", "run_headline", "run_kind", "run_temper"]

KINDS = ("temper", "headline", "bias", "net-field")
HELPS = {
    "temper": "tempering exponents beta of p~(m)^beta on validation plans by unseen-cell NLL (temper_CORPUS.json)",
    "headline": "the headline experiment's prior, by best F1 on sparse scans of validation plans (headline_prior.json)",
    "bias": "a bias h per prior so that it fills an empty window as its corpus is filled (bias.json)",
    "net-field": "a net field: a small network on every window, by pseudo-likelihood then PCD (net_NAME.npz + .json)",
}


def _out(k: argparse.ArgumentParser, ship: str | None, required: bool = True) -> None:
    where = k.add_mutually_exclusive_group(required=required)
    where.add_argument("--out", type=Path, default=None, help="the folder the fitted files go to")
    if ship:
        where.add_argument(
            "--ship",
            action="store_true",
            help=f"maintainers: replace the package's {ship}" + ("" if required else " (the default without --out)"),
        )
    k.add_argument("--quiet", action="store_true", help="no progress output")


def _scan(k: argparse.ArgumentParser, d: Any) -> None:
    k.add_argument("--plans", type=int, default=d.plans, help="validation plans scored (%(default)s)")
    k.add_argument("--window", type=int, default=d.window, help="cells a side of each plan's window (%(default)s)")
    k.add_argument("--poses", type=int, default=d.poses, help="stops of the simulated scan (%(default)s)")
    k.add_argument("--beams", type=int, default=d.beams, help="beams a scan (%(default)s)")
    k.add_argument("--range-cells", type=float, default=d.range_cells, help="maximum range, cells (%(default)s)")
    k.add_argument("--sigma", type=float, default=d.sigma, help="range noise, cells (%(default)s)")
    k.add_argument("--sweeps", type=int, default=d.sweeps, help="sweeps kept per chain (%(default)s)")
    k.add_argument("--burn", type=int, default=d.burn, help="burn-in sweeps (%(default)s)")
    k.add_argument("--seed", type=int, default=d.seed, help="seed of the scans and chains (%(default)s)")
    k.add_argument("--fit-limit", type=int, default=None, help="count tables on the first N fit plans only (all)")


def add_temper(k: argparse.ArgumentParser, *, ship_by_default: bool = False) -> None:
    """The options of ``fit-prior temper``; ``ship_by_default`` (``experiments/fit_temper.py``): ``--corpus``
    defaults to every corpus and neither ``--out`` nor ``--ship`` is required (the caller ships without one)."""
    from ogm_ppl.learn._fit_common import CORPORA
    from ogm_ppl.learn.temper import TemperSettings

    d = TemperSettings()
    if ship_by_default:
        k.add_argument("--corpus", nargs="+", choices=CORPORA, default=list(CORPORA), help="the corpora (all)")
    else:
        k.add_argument("--corpus", nargs="+", choices=CORPORA, required=True, help="the corpora (one file each)")
    k.add_argument("--kinds", nargs="+", default=list(d.kinds), metavar="KIND", help="prior kinds (the tables')")
    k.add_argument("--betas", nargs="+", type=float, default=list(d.betas), help="exponents tried, in [0, 1]")
    _scan(k, d)
    k.add_argument("--generated-shape", type=int, default=d.generated_shape, help="generated maps' side (160)")
    k.add_argument("--max-support", type=int, default=d.max_support, help="skip kinds whose update weighs more")
    k.add_argument("--kernel", default=d.kernel, help="the chains' sampler (gibbs, cycle, shifted-cycle, ...)")
    k.add_argument("--update", action="store_true", help="keep the other kinds of the file there; refit --kinds")
    k.add_argument(
        "--sample",
        type=int,
        default=None,
        help="split a random N of the corpus's training plans (as its tables were counted: houseexpo-full 1000)",
    )
    k.add_argument("--sample-seed", type=int, default=None, help="the seed of --sample (0)")
    k.add_argument(
        "--quick",
        action="store_true",
        help="smoke run: the first corpus given (dungeon if all), 2 plans of 48 cells, 10 + 4 sweeps, the first 2 "
        "kinds and betas, tables of 10 fit plans",
    )
    _out(k, "ogm_ppl/fitted/temper_CORPUS.json", required=not ship_by_default)


def quick_temper(args: argparse.Namespace) -> argparse.Namespace:
    """``args`` with ``--quick``'s settings in place of the scan's, the kinds', the betas' and the corpora's."""
    from ogm_ppl.learn._fit_common import CORPORA

    if args.quick:
        args.plans, args.window, args.sweeps, args.burn = 2, 48, 10, 4
        args.betas, args.kinds = args.betas[:2], args.kinds[:2]
        args.corpus = args.corpus[:1] if len(args.corpus) < len(CORPORA) else ["dungeon"]
        args.fit_limit = 10 if args.fit_limit is None else args.fit_limit
    return args


def run_temper(args: argparse.Namespace) -> Any:
    from ogm_ppl.learn.temper import TemperSettings, fit_temper

    args = quick_temper(args)
    s = TemperSettings(
        kinds=tuple(args.kinds),
        betas=tuple(args.betas),
        plans=args.plans,
        window=args.window,
        generated_shape=args.generated_shape,
        poses=args.poses,
        beams=args.beams,
        range_cells=args.range_cells,
        sigma=args.sigma,
        sweeps=args.sweeps,
        burn=args.burn,
        seed=args.seed,
        max_support=args.max_support,
        kernel=args.kernel,
        fit_limit=args.fit_limit,
        sample=args.sample,
        sample_seed=sample_seed(args),
    )
    out = None if args.ship else args.out
    return fit_temper(args.corpus, out, settings=s, update=args.update, ship=args.ship, progress=not args.quiet)


def add_headline(k: argparse.ArgumentParser, *, ship_by_default: bool = False) -> None:
    """The options of ``fit-prior headline``; ``ship_by_default`` (``experiments/select_headline_prior.py``):
    neither ``--out`` nor ``--ship`` is required (the caller ships without one)."""
    from ogm_ppl.learn.headline import HEADLINE_CORPORA, HeadlineSettings

    d = HeadlineSettings()
    k.add_argument("--corpus", default=d.corpus, choices=HEADLINE_CORPORA, help="the corpus (%(default)s)")
    k.add_argument(
        "--candidates",
        nargs="+",
        default=[f"{a}/{b}" for a, b in d.candidates],
        metavar="KIND/UPDATE",
        help="prior kind and patch-Gibbs update (gibbs, thesis) of each candidate (the shipped six)",
    )
    _scan(k, d)
    k.add_argument("--name", default="headline_prior", help="the file's name part (headline_prior)")
    k.add_argument(
        "--quick",
        action="store_true",
        help="smoke run: 2 plans of 64 cells, 6 + 2 sweeps, the first 2 candidates, tables of 10 fit plans",
    )
    _out(k, "ogm_ppl/fitted/headline_prior.json", required=not ship_by_default)


def quick_headline(args: argparse.Namespace) -> argparse.Namespace:
    """``args`` with ``--quick``'s settings in place of the scan's and the candidates'."""
    if args.quick:
        args.plans, args.window, args.sweeps, args.burn = 2, 64, 6, 2
        args.candidates = args.candidates[:2]
        args.fit_limit = 10 if args.fit_limit is None else args.fit_limit
    return args


def run_headline(args: argparse.Namespace) -> Any:
    from ogm_ppl.learn.headline import HeadlineSettings, candidates_from, select_headline_prior

    args = quick_headline(args)
    s = HeadlineSettings(
        corpus=args.corpus,
        plans=args.plans,
        window=args.window,
        poses=args.poses,
        beams=args.beams,
        range_cells=args.range_cells,
        sigma=args.sigma,
        sweeps=args.sweeps,
        burn=args.burn,
        seed=args.seed,
        candidates=candidates_from(args.candidates),
        fit_limit=args.fit_limit,
    )
    out = None if args.ship else args.out
    return select_headline_prior(out, settings=s, name=args.name, ship=args.ship, progress=not args.quiet)


def add_bias(k: argparse.ArgumentParser) -> None:
    from ogm_ppl.learn._fit_common import CORPORA, SHIPPED_CORPORA
    from ogm_ppl.learn.bias import PRIORS, BiasSettings

    d = BiasSettings()
    k.add_argument("--priors", nargs="+", default=list(PRIORS), metavar="KIND", help="prior kinds (KIND[@cal])")
    k.add_argument(
        "--train", nargs="+", default=list(SHIPPED_CORPORA), choices=CORPORA, help="corpora the priors learned on"
    )
    k.add_argument("--window", type=int, default=d.window, help="cells a side of the empty window (%(default)s)")
    k.add_argument("--sweeps", type=int, default=d.sweeps, help="sweeps per chain (%(default)s)")
    k.add_argument("--every", type=int, default=d.every, help="record the occupied share every N sweeps (50)")
    k.add_argument("--seed", type=int, default=d.seed, help="seed of the chains (%(default)s)")
    k.add_argument("--bias-range", type=float, default=d.bias_range, help="bisection interval [-R, R] of h (2)")
    k.add_argument("--bias-steps", type=int, default=d.bias_steps, help="bisection steps (%(default)s)")
    _out(k, None)


def run_bias(args: argparse.Namespace) -> Any:
    from ogm_ppl.learn.bias import BiasSettings, fit_bias

    s = BiasSettings(
        window=args.window,
        sweeps=args.sweeps,
        every=args.every,
        seed=args.seed,
        bias_range=args.bias_range,
        bias_steps=args.bias_steps,
    )
    return fit_bias(args.priors, args.out, train=args.train, settings=s, progress=not args.quiet)


_NET_HELP = {
    "w": "window side, cells",
    "hidden": "filters, each used in its 8 orientations (8 units each)",
    "activation": "the units' nonlinearity: relu or softplus",
    "pad": "the value a cell past the grid's edge reads as, in [0, 1]",
    "lambda_": "L2 penalty on the filters, biases and output weights",
    "pl_steps": "pseudo-likelihood Adam steps",
    "pl_batch": "training cells a pseudo-likelihood step",
    "pl_lr": "pseudo-likelihood step size (falls to a 20th on a half cosine)",
    "pcd_steps": "persistent contrastive divergence steps after pseudo-likelihood",
    "pcd_chains": "persistent chains (and training crops a step)",
    "pcd_size": "side of the chains' and crops' grids, cells",
    "pcd_sweeps": "compiled Gibbs sweeps of the chains a step",
    "pcd_lr": "PCD step size",
    "eval_every": "steps between held-out scores and checkpoints",
    "check_size": "grid side of the final sampler check",
    "check_sweeps": "sweeps of the final sampler check",
    "seed": "seed of the initial weights, batches, crops and chains",
    "start": "a net-field file whose parameters start the fit (then --pl-steps may be 0)",
    "start_beta": "the PCD stage starts from the field raised to this power, in (0, 1]",
    "pcd_init": "the PCD chains start from training crops (data) or uniform noise (noise)",
    "select": "stopping score: held-out pseudo-likelihood (pl) or unseen-cell NLL of scanned validation windows",
    "select_plans": "validation windows of the unseen-cell score",
    "select_window": "side of those windows, cells",
    "select_sweeps": "Gibbs sweeps a chain of the unseen-cell score (after 5)",
}


def sample_seed(args: argparse.Namespace) -> int:
    """``--sample-seed`` (default 0), refused without ``--sample``: it would pick nothing."""
    from ogm_ppl.learn import FitOptionError

    if args.sample_seed is not None and args.sample is None:
        raise FitOptionError("sample_seed", "applies with --sample only (the seed of its random plans)")
    return 0 if args.sample_seed is None else args.sample_seed


def add_net_field(k: argparse.ArgumentParser) -> None:
    from dataclasses import fields

    from ogm_ppl.learn._fit_common import CORPORA
    from ogm_ppl.learn.net_field import NetFieldSettings

    src = k.add_mutually_exclusive_group(required=True)
    src.add_argument("--corpus", choices=CORPORA, help="fit on this corpus's training plans")
    src.add_argument("--plan-files", nargs="+", type=Path, metavar="PATH", help="plan files or folders of them")
    k.add_argument("--limit", type=int, default=None, help="the first N training plans (default: the corpus's)")
    k.add_argument("--sample", type=int, default=None, help="a random N of the corpus's training plans")
    k.add_argument("--sample-seed", type=int, default=None, help="the seed of --sample (0)")
    k.add_argument("--pixel-size", type=float, default=None, help="metres per pixel of plan images")
    k.add_argument("--resolution", type=float, default=0.05, help="metres per cell of plan files (0.05)")
    k.add_argument("--name", default=None, help="the files' name part (default the corpus, or 'plans')")
    k.add_argument("--validation-every", type=int, default=10, help="every N-th plan is validation (%(default)s)")
    k.add_argument("--no-resume", action="store_true", help="ignore a checkpoint in --out, start afresh")
    for f in fields(NetFieldSettings):
        flag = "--" + f.name.replace("_", "-").rstrip("-")
        kind = f.type if callable(f.type) else {"int": int, "float": float, "str": str}[str(f.type)]
        help = _NET_HELP[f.name] + " (%(default)s)"
        k.add_argument(flag, dest=f"s_{f.name}", type=kind, default=f.default, metavar=f.name.upper(), help=help)
    _out(k, "ogm_ppl/fitted/net_CORPUS.npz + .json (with --corpus)")


def run_net_field(args: argparse.Namespace) -> Any:
    from dataclasses import fields

    from ogm_ppl.learn import FitOptionError, load_training_plans
    from ogm_ppl.learn.net_field import NetFieldSettings, fit_net_field

    s = NetFieldSettings(**{f.name: getattr(args, f"s_{f.name}") for f in fields(NetFieldSettings)})
    out, name = args.out, args.name
    source = args.corpus if args.corpus is not None else list(args.plan_files)
    seed = sample_seed(args)  # refused without --sample
    if args.sample is not None:  # a random subset of a corpus's training plans, recorded in the provenance
        source = load_training_plans(source, limit=args.limit, sample=args.sample, sample_seed=seed)
    if args.ship:
        from ogm_ppl.priors.net_field import net_path

        if args.corpus is None:
            raise FitOptionError("ship", "ships a corpus's fit: give --corpus")
        out, name = net_path(args.corpus).parent, args.corpus
    return fit_net_field(
        source,
        out,
        settings=s,
        limit=None if args.sample is not None else args.limit,
        pixel_size=args.pixel_size,
        resolution=args.resolution,
        name=name,
        validation_every=args.validation_every,
        resume=not args.no_resume,
        progress=not args.quiet,
    )


_ADD: dict[str, Callable[[argparse.ArgumentParser], None]] = {
    "temper": add_temper,
    "headline": add_headline,
    "bias": add_bias,
    "net-field": add_net_field,
}
_RUN: dict[str, Callable[[argparse.Namespace], Any]] = {
    "temper": run_temper,
    "headline": run_headline,
    "bias": run_bias,
    "net-field": run_net_field,
}


def add_kind(kinds: argparse._SubParsersAction, kind: str) -> None:
    """Add the sub-subcommand ``kind`` (one of :data:`KINDS`) with its options."""
    _ADD[kind](kinds.add_parser(kind, help=HELPS[kind], description=HELPS[kind]))


def run_kind(args: argparse.Namespace) -> Any:
    """Run ``args.kind``; the :class:`~ogm_ppl.learn.FitResult`."""
    return _RUN[args.kind](args)
