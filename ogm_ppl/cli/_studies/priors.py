"""The studies of the priors: ``prior_stats``, ``prior_occupancy``, ``border_chain_probe`` and ``path_free``
(:mod:`ogm_ppl.cli._studies`)."""

from __future__ import annotations

import argparse
from pathlib import Path

from ogm_ppl.cli._studies import Study


# ---------------------------------------------------------------------------------------------- prior_stats
def _prior_stats_arguments(ap: argparse.ArgumentParser) -> None:
    ap.add_argument("--fit", action="store_true", help="re-learn the tables first")
    ap.add_argument(
        "--quick", action="store_true", help="tiny corpora; the tables go to prior_tables_quick/ beside --out"
    )
    ap.add_argument("--out", default="out/prior_stats", help="output path stem (out/prior_stats)")


def _prior_stats_run(args: argparse.Namespace) -> dict:
    from ogm_ppl.priors.tables import FITTED_DIR
    from ogm_ppl.studies.prior_stats import QUICK_LIMITS, fit_corpus_tables, prior_stats, prior_stats_markdown

    out = Path(args.out)
    table_dir = out.parent / "prior_tables_quick" if args.quick else FITTED_DIR
    timings = None
    if args.fit:
        fits = fit_corpus_tables(table_dir, QUICK_LIMITS if args.quick else None)
        for name, r in fits.items():
            print(f"{name}: {r.files[0]} {r.files[0].stat().st_size / 1e6:.2f} MB, {r.seconds} s", flush=True)
        timings = {name: r.seconds for name, r in fits.items()}
    doc = prior_stats(table_dir, out.parent, name=out.stem, timings=timings)
    print(prior_stats_markdown(doc))
    return doc


PRIOR_STATS = Study(
    """The command line of :func:`ogm_ppl.studies.prior_stats.prior_stats` (the statistics are in
:mod:`ogm_ppl.studies.prior_stats`): the thesis's patch statistics of the prior tables per corpus (Section
5.2.2-5.2.3), written to OUT.md and OUT.json. --fit is :func:`ogm_ppl.learn.fit_tables` of each corpus
(``ogm-ppl fit-prior tables --corpus C --out DIR``) into the package's tables, or with --quick into
prior_tables_quick/ beside --out.

    ogm-ppl study prior_stats                  # statistics of the shipped tables -> out/prior_stats.{md,json}
    ogm-ppl study prior_stats --fit --quick    # tiny corpora, for a smoke test (writes under out/ only)""",
    _prior_stats_arguments,
    _prior_stats_run,
)


# ------------------------------------------------------------------------------------------ prior_occupancy
def _prior_occupancy_arguments(ap: argparse.ArgumentParser) -> None:
    from ogm_ppl.studies.prior_occupancy import PRIORS, TRAIN

    ap.add_argument("--priors", nargs="+", default=list(PRIORS), help="prior kinds (KIND[@cal])")
    ap.add_argument("--train", nargs="+", default=list(TRAIN), choices=TRAIN, help="corpora the priors learned on")
    ap.add_argument("--window", type=int, default=96, help="cells a side (default 96, the calibration window)")
    ap.add_argument("--sweeps", type=int, default=1000, help="sweeps per chain (default 1000)")
    ap.add_argument("--every", type=int, default=50, help="record the occupied share every this many sweeps")
    ap.add_argument("--seed", type=int, default=0, help="seed of the chains (0)")
    ap.add_argument(
        "--fit-bias",
        action="store_true",
        help="also fit each prior's bias h (BiasedPrior) to its corpus's share; writes OUT/bias.json",
    )
    ap.add_argument("--bias-range", type=float, default=2.0, help="bisection interval [-R, R] of h (default 2)")
    ap.add_argument("--bias-steps", type=int, default=7, help="bisection steps (default 7)")
    ap.add_argument("--out", type=Path, default=Path("out/prior_occupancy"), help="the output folder")


def _prior_occupancy_run(args: argparse.Namespace) -> dict:
    from ogm_ppl.learn.bias import BiasSettings
    from ogm_ppl.studies.prior_occupancy import prior_occupancy, prior_occupancy_lines

    settings = BiasSettings(args.window, args.sweeps, args.every, args.seed, args.bias_range, args.bias_steps)
    doc = prior_occupancy(args.priors, args.train, settings, args.out, fit_bias=args.fit_bias)
    print("\n".join(prior_occupancy_lines(doc)))
    print(f"wrote {args.out / 'prior_occupancy.json'} ({doc['seconds']:.0f} s)")
    return doc


PRIOR_OCCUPANCY = Study(
    """How much of a region with no readings does a prior fill? Each prior's own occupied share against its
corpus's. The command line of :func:`ogm_ppl.studies.prior_occupancy.prior_occupancy` (the chains, the shares and
the moment-matching argument are in :mod:`ogm_ppl.studies.prior_occupancy`). --fit-bias also fits each prior's
bias h (:func:`ogm_ppl.learn.fit_bias`, ``ogm-ppl fit-prior bias``) and writes OUT/bias.json, which
``ogm-ppl calibrate --bias-file`` reads.

    ogm-ppl study prior_occupancy --train dungeon houseexpo       # a few minutes

Writes OUT/prior_occupancy.json (settings, provenance, one row per prior with each chain's trace) and prints a
table.""",
    _prior_occupancy_arguments,
    _prior_occupancy_run,
)


# --------------------------------------------------------------------------------------- border_chain_probe
def _border_chain_probe_arguments(ap: argparse.ArgumentParser) -> None:
    ap.add_argument("folder", type=Path, help="an experiment's output folder (ogm-ppl experiment --out)")
    ap.add_argument("dataset", help="a dataset of the experiment")
    ap.add_argument("--sweeps", type=int, default=12, help="sweeps of the chain (12)")
    ap.add_argument("--sigma", type=float, default=3.0, help="range noise, cells (3)")


def _border_chain_probe_run(args: argparse.Namespace) -> dict:
    from ogm_ppl.studies.border_chain_probe import border_chain_probe, border_chain_probe_lines

    doc = border_chain_probe(args.folder, args.dataset, args.sweeps, args.sigma)
    print("\n".join(border_chain_probe_lines(doc)))
    return doc


BORDER_CHAIN_PROBE = Study(
    """Why the border prior trails on simulated office maps (README, Table 6.4): prior mass and likelihood of a
3 x 3 patch Gibbs chain with border:generated from the thresholded OGM start, sweep by sweep, beside the true
map's; and the true map's tiles whose (border, inner) pair the tables never counted. The command line of
:func:`ogm_ppl.studies.border_chain_probe.border_chain_probe`.

    ogm-ppl study border_chain_probe out/experiments/table_6_4_small sim-m1000 [--sweeps 12]""",
    _border_chain_probe_arguments,
    _border_chain_probe_run,
)


# ------------------------------------------------------------------------------------------------ path_free
def _path_free_arguments(ap: argparse.ArgumentParser) -> None:
    from ogm_ppl.studies.path_free import PathFreeSettings

    d = PathFreeSettings()
    ap.add_argument(
        "--corpus", default=d.corpus, help=f"the corpus whose held-out plans the scenes come from ({d.corpus})"
    )
    ap.add_argument(
        "--priors", nargs="+", default=list(d.priors), help="prior names (default: " + " ".join(d.priors) + ")"
    )
    ap.add_argument("--scenes", type=int, default=d.scenes, help=f"scenes ({d.scenes})")
    ap.add_argument("--rows", type=int, default=d.rows, help=f"rows of a scene's window ({d.rows}; rows x cols <= 24)")
    ap.add_argument("--cols", type=int, default=d.cols, help=f"columns of a scene's window ({d.cols})")
    ap.add_argument("--beams", type=int, default=d.beams, help=f"beams of the robot's scan ({d.beams})")
    ap.add_argument("--range-cells", type=float, default=d.range_cells, help=f"beam range, cells ({d.range_cells:g})")
    ap.add_argument("--sigma", type=float, default=d.sigma, help=f"range noise, cells ({d.sigma:g})")
    ap.add_argument("--seed", type=int, default=d.seed, help=f"seed of the scenes and scans ({d.seed})")
    ap.add_argument("--plans", type=int, default=d.plans, help=f"held-out plans the scenes are cut from ({d.plans})")
    ap.add_argument(
        "--scenes-per-plan", type=int, default=d.scenes_per_plan, help=f"scenes at most per plan ({d.scenes_per_plan})"
    )
    ap.add_argument("--out", type=Path, default=Path("out/path_free"), help="the output folder (out/path_free)")
    ap.add_argument("--quiet", action="store_true", help="no progress lines")


def _path_free_run(args: argparse.Namespace) -> dict:
    from ogm_ppl.provenance import command_line
    from ogm_ppl.studies.path_free import FILE_NAME, PathFreeSettings, path_free, path_free_lines

    settings = PathFreeSettings(
        corpus=args.corpus, priors=tuple(args.priors), scenes=args.scenes, rows=args.rows, cols=args.cols,
        beams=args.beams, range_cells=args.range_cells, sigma=args.sigma, seed=args.seed, plans=args.plans,
        scenes_per_plan=args.scenes_per_plan,
    )  # fmt: skip
    doc = path_free(settings, args.out, command=command_line(), progress=not args.quiet)
    print("\n".join(path_free_lines(doc)))
    print(f"wrote {args.out / FILE_NAME} ({doc['seconds']:.0f} s)")
    return doc


PATH_FREE = Study(
    """Is a path free? The exact joint answer against the product of marginals, and both against the truth. The
command line of :func:`ogm_ppl.studies.path_free.path_free` (the scenes, the paths and the scores are in
:mod:`ogm_ppl.studies.path_free`): on enumerable windows cut from held-out plans, with a robot's scan, every
straight path holding an unseen cell gets the posterior's exact P(path free) and the product of its marginals,
per prior, scored against the plan. Writes OUT/path_free.json and prints one line per prior.

    ogm-ppl study path_free                                   # 60 scenes of 4 x 4 cells, three priors
    ogm-ppl study path_free --scenes 4 --priors independent:houseexpo patch3:houseexpo --out /tmp/pf""",
    _path_free_arguments,
    _path_free_run,
)

STUDIES = {
    "prior_stats": PRIOR_STATS,
    "prior_occupancy": PRIOR_OCCUPANCY,
    "border_chain_probe": BORDER_CHAIN_PROBE,
    "path_free": PATH_FREE,
}
