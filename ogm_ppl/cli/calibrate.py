r"""``ogm-ppl calibrate``: priors and guides as predictors of what was not seen, and how well calibrated they are
(thesis Chapter 5, 5.2.1-5.2.3; :func:`ogm_ppl.calibration.calibrate`).

On held-out maps of each test corpus (``--test``: ``generated`` maps from seeds no shipped table counted; the
held-out plans of ``houseexpo``, ``ipa``, ``dungeon`` by default, or of ``houseexpo-full``, ``r2v``, ``schools``
named; the buildings of the real logs left out) a
``--window`` crop is scanned sparsely (``--poses`` stops of ``--beams`` beams) and the posterior marginals are
estimated with every prior (``--priors``) learned on every training corpus (``--train``) by 3 chains of Gibbs
sampling (``--kernel``, ``--sweeps`` after ``--burn``; patch Gibbs over the tile of a prior whose compiled
bundle weighs a sparse support, skipped over ``--max-support`` configurations). Traditional OGM with the fitted
``p21`` update is the baseline row. ``KIND@cal`` is a kind raised to the tempering exponent that
``ogm-ppl fit-prior temper`` (:func:`ogm_ppl.learn.fit_temper`) fitted; ``--diagonal`` scores each test corpus
with the priors learned on it only.

``--guides C ...`` adds a ``guide:C`` row, the one-pass marginals of the amortised guide learned on corpus
``C`` (``houseexpo+ipa``: on both; ``@sym``: averaged over the 8 turns and flips of the window), checked
against the training set of each corpus it was learned on. ``--bias-file bias.json``
(``ogm-ppl fit-prior bias``, :func:`ogm_ppl.learn.fit_bias`) also runs every prior it names as ``NAME+bias``.

``--plan-files PATH ...`` (ROS map YAMLs, HouseExpo layouts, images with ``--pixel-size``, or folders of them)
adds one more test set, labelled ``--plan-set``, scored with every prior of every ``--train`` corpus and every
guide (without ``--guides``, the floor-plan guide); without ``--test`` only the plan set runs. A file that is a
corpus plan, a near copy of one, or a layout under a corpus plan's HouseExpo id is refused.

Scored: the near-mapped cells (within 10 cells of a reached cell) and their unseen cells: NLL in bits per cell,
ECE and reliability diagram, Brier score, ROC AUC, best F1, IoU, seconds, and the share of unseen cells whose
chains agree (split R-hat < 1.05). A prior is never scored on a map it was learned from (checked before
anything runs).

Writes under ``--out`` (default ``out/calibration``): ``calibration.json``, ``calibration_summary.json``,
``calibration.md``, ``reliability_<test>.png``, ``bars_<mask>.png`` and ``matrix_unseen.png``. A rerun with the
same settings resumes, computing again only the rows of a prior or guide that changed.

    ogm-ppl calibrate --quick        # smoke run, 1 small map per corpus, 3 priors
    ogm-ppl calibrate                # the default matrix (about an hour on 2 cores)
    ogm-ppl calibrate --priors patch3 border --train houseexpo --test ipa dungeon
    ogm-ppl calibrate --plan-files my_plans/ --pixel-size 0.05 --guides houseexpo+ipa@sym

A subcommand of :mod:`ogm_ppl.cli`: :func:`add_parser` adds it, :func:`run` runs it
(:func:`ogm_ppl.calibration.calibrate` with :func:`settings_from_args`).
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from ogm_ppl.calibration.chains import KERNELS
from ogm_ppl.calibration.errors import SettingsError
from ogm_ppl.calibration.heldout import PLAN_FILES_GUIDE, PLAN_FILES_PRIORS, TEST_CORPORA
from ogm_ppl.calibration.run import calibrate
from ogm_ppl.calibration.settings import PLAN_OUTSIDE, CalibrationSettings
from ogm_ppl.cli._common import CLIError
from ogm_ppl.inference.mcmc.tempering import TEMPERS

__all__ = [
    "NAME",
    "add_arguments",
    "add_parser",
    "add_plan_file_arguments",
    "build_parser",
    "check_plan_file_arguments",
    "run",
    "settings_from_args",
]

#: the subcommand's name
NAME = "calibrate"
HELP = "score priors and guides as predictors of unseen cells on held-out maps (thesis 5.2)"


def add_plan_file_arguments(ap: argparse.ArgumentParser) -> None:
    """``--plan-files``, ``--plan-set``, ``--pixel-size`` and ``--plan-outside`` (the commands and scripts that
    score held-out maps take plans of other buildings alike; :func:`check_plan_file_arguments`)."""
    ap.add_argument(
        "--plan-files",
        nargs="+",
        type=Path,
        default=None,
        metavar="PATH",
        help="also score plans of other buildings: ROS map YAMLs, HouseExpo layouts (.json) or images, or folders "
        "of them (ogm_ppl.datasets.plan_files), as one more test set",
    )
    ap.add_argument("--plan-set", default="files", help="the label of the --plan-files test set (default files)")
    ap.add_argument(
        "--pixel-size", type=float, default=None, help="metres per pixel of --plan-files images (a YAML has its own)"
    )
    ap.add_argument(
        "--plan-outside",
        default="occupied",
        choices=PLAN_OUTSIDE,
        help="a plan file's unknown and exterior cells: occupied and scored, as the corpora's (default), or unknown: "
        "walls to the simulated sensor, never scored (for maps built from logs, whose unknown cells include "
        "rooms nobody entered)",
    )


def check_plan_file_arguments(ap: argparse.ArgumentParser, args: argparse.Namespace) -> None:
    """Refuse (``ap.error``) ``--plans`` below 1, a plan-set label that is not a plain name or is a test corpus's
    name (in any case) or ``none``, and plan-file options without ``--plan-files``: the checks of
    :class:`~ogm_ppl.calibration.settings.CalibrationSettings` on these options."""
    try:
        CalibrationSettings(
            plans=args.plans,
            plan_files=args.plan_files,
            plan_set=args.plan_set,
            pixel_size=args.pixel_size,
            plan_outside=args.plan_outside,
        )
    except SettingsError as e:
        ap.error(f"{e.flag}: {e.reason}")


def add_arguments(ap: argparse.ArgumentParser) -> None:
    """Every option of ``ogm-ppl calibrate`` (a field of
    :class:`~ogm_ppl.calibration.settings.CalibrationSettings` each, and ``--out``)."""
    ap.add_argument(
        "--test",
        nargs="+",
        default=None,
        choices=TEST_CORPORA,
        help="test corpora (default: generated houseexpo ipa dungeon, or none where --plan-files is given)",
    )
    add_plan_file_arguments(ap)
    ap.add_argument(
        "--train",
        nargs="+",
        default=None,
        help="training corpora of the tables (default: the shipped tables of the default --test corpora)",
    )
    ap.add_argument(
        "--priors",
        nargs="+",
        default=None,
        help="prior kinds or names (default: every kind, and KIND@cal where fitted; with --plan-files alone, "
        f"{' '.join(PLAN_FILES_PRIORS)})",
    )
    ap.add_argument(
        "--guides",
        nargs="*",
        default=None,
        help="also score the amortised guide learned on each of these corpora (guide:CORPUS rows; "
        "ogm-ppl train-guide); CORPUS@sym: the guide symmetrised (default: none, or with "
        f"--plan-files the floor-plan guide {PLAN_FILES_GUIDE})",
    )
    ap.add_argument(
        "--guide-dir",
        default=None,
        help="read the --guides as DIR/guide_CORPUS.npz (default: the shipped ones in ogm_ppl/fitted); their "
        "records are checked against the tables' training sets all the same",
    )
    ap.add_argument(
        "--diagonal",
        action="store_true",
        help="score each test corpus only with the priors learned on it (every guide still runs on every corpus)",
    )
    ap.add_argument(
        "--plans", type=int, default=None, help="held-out maps per test corpus (default 2; every plan of --plan-files)"
    )
    ap.add_argument("--window", type=int, default=96, help="maps are cropped to this many cells a side")
    ap.add_argument("--generated-shape", type=int, default=160, help="side of the held-out generated maps")
    ap.add_argument("--poses", type=int, default=3, help="stops of the sparse route")
    ap.add_argument("--beams", type=int, default=90, help="beams per 360-degree scan")
    ap.add_argument("--range-cells", type=float, default=75.0, help="maximum range, cells")
    ap.add_argument("--sigma", type=float, default=1.0, help="range noise, cells")
    ap.add_argument("--sweeps", type=int, default=200, help="kept sweeps per chain")
    ap.add_argument("--burn", type=int, default=50, help="warm-up sweeps per chain")
    ap.add_argument("--seed", type=int, default=0, help="seed of the scans (and of chain c: seed + 1000 c)")
    ap.add_argument("--kernel", default="gibbs", choices=sorted(KERNELS), help="sampler (an entry of KERNELS)")
    ap.add_argument(
        "--rungs", type=int, default=None, help="tempering: rungs of the geometric ladder, the cold one in (default 6)"
    )
    ap.add_argument(
        "--beta-min", type=float, default=None, help="tempering: the hottest rung's exponent, in (0, 1) (default 0.1)"
    )
    ap.add_argument(
        "--temper", default=None, choices=TEMPERS, help="tempering: the factor the ladder raises (default prior)"
    )
    ap.add_argument(
        "--proposal-guide",
        default=None,
        help=f"guided: the corpus guide proposing blocks of cells (C, C1+C2, either @sym; default {PLAN_FILES_GUIDE})",
    )
    ap.add_argument("--patch", nargs="*", default=[], help="per-kind patch override: KIND=RxC or KIND=1")
    ap.add_argument(
        "--bias-file",
        type=Path,
        default=None,
        help="bias.json of ogm-ppl fit-prior bias: each prior it names also runs biased (NAME+bias)",
    )
    ap.add_argument(
        "--max-support",
        type=int,
        default=4096,
        help="skip a prior whose patch update weighs more configurations than this (5 x 5 tables)",
    )
    ap.add_argument("--out", type=Path, default=Path("out/calibration"), help="output folder (default out/calibration)")
    ap.add_argument("--fresh", action="store_true", help="ignore rows already in the output JSON")
    ap.add_argument("--no-figures", action="store_true", help="write no PNG figures")
    ap.add_argument("--quick", action="store_true", help="smoke run: 1 map of 48 cells per corpus, 3 priors")


def add_parser(sub: argparse._SubParsersAction) -> None:
    """Register ``calibrate`` with the subcommands of ``ogm-ppl``."""
    p = sub.add_parser(NAME, help=HELP, description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_arguments(p)


def build_parser(prog: str | None = None, description: str | None = None) -> argparse.ArgumentParser:
    """A stand-alone parser of the ``calibrate`` options (for a script that runs the protocol)."""
    ap = argparse.ArgumentParser(
        prog=prog, description=description or __doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    add_arguments(ap)
    return ap


#: the options that only one sampler reads, by ``--kernel``: named with another sampler they are refused
KERNEL_OPTIONS: dict[str, tuple[str, ...]] = {
    "tempering": ("rungs", "beta_min", "temper"),
    "guided": ("proposal_guide",),
}


def _kernel_options(args: argparse.Namespace) -> dict[str, Any]:
    """The sampler-specific settings of ``args``: each named option for its own ``--kernel`` (the settings'
    default where it is not named); one named for another sampler raises :class:`SettingsError` (it would be
    taken and ignored)."""
    defaults = CalibrationSettings.__dataclass_fields__
    out: dict[str, Any] = {}
    for kernel, fields in KERNEL_OPTIONS.items():
        for f in fields:
            given = getattr(args, f, None)
            if given is not None and args.kernel != kernel:
                raise SettingsError(f, f"applies to --kernel {kernel} only, not --kernel {args.kernel}")
            out[f] = defaults[f].default if given is None else given
    return out


def settings_from_args(args: argparse.Namespace) -> CalibrationSettings:
    """The :class:`~ogm_ppl.calibration.settings.CalibrationSettings` of parsed ``calibrate`` options; raises
    :class:`~ogm_ppl.calibration.errors.SettingsError` for a value out of range, or for a sampler's own option
    (:data:`KERNEL_OPTIONS`) named with another ``--kernel``."""
    kernel_options = _kernel_options(args)
    return CalibrationSettings(
        test=args.test,
        train=args.train,
        priors=args.priors,
        guides=args.guides,
        guide_dir=args.guide_dir,
        diagonal=args.diagonal,
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
        kernel=args.kernel,
        **kernel_options,
        patch=tuple(args.patch),
        bias_file=args.bias_file,
        max_support=args.max_support,
        plan_files=None if args.plan_files is None else tuple(args.plan_files),
        plan_set=args.plan_set,
        pixel_size=args.pixel_size,
        plan_outside=args.plan_outside,
        fresh=args.fresh,
        figures=not args.no_figures,
        quick=args.quick,
    )


def run(args: argparse.Namespace) -> int:
    """Run ``ogm-ppl calibrate`` with parsed options: :func:`~ogm_ppl.calibration.run.calibrate` into
    ``args.out``; returns the exit status 0. A bad option raises :class:`~ogm_ppl.cli._common.CLIError`
    (``--option: reason``); the workflow's other refusals (:data:`~ogm_ppl.calibration.errors.USER_ERRORS`,
    all ``ValueError``) pass through, for :func:`ogm_ppl.cli.main` to print."""
    try:
        settings = settings_from_args(args)
    except SettingsError as e:
        raise CLIError(f"{e.flag}: {e.reason}") from None
    try:
        calibrate(settings, args.out, progress=True)
    except SettingsError as e:  # the output folder, a patch override
        raise CLIError(f"{e.flag}: {e.reason}") from None
    return 0
