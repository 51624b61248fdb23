"""The studies of :mod:`ogm_ppl.studies` as command lines: ``ogm-ppl study NAME [options]``.

Each study is a :class:`Study`: its one-line summary, its description, ``add_arguments(parser)`` (the options,
their defaults and help, defined here once) and ``run(args)`` (runs the study's function, prints what the
command prints and returns the result, or an exit status). The studies live in the modules of this package by
theme; :data:`STUDIES` names each study's module, so a command imports only the study it runs.

``ogm-ppl study NAME`` (:mod:`ogm_ppl.cli.study`) and the scripts of the repository's ``experiments/``
(:func:`script_main`) both build the parser of :func:`build_parser` and call :func:`run_study`: a bad option or
setting is refused by the parser (one line, exit status 2); a bad input (a folder that is not an experiment's,
a missing file) is the study's typed error, which the command prints as one line (exit status 2) and a script
as ``SCRIPT: message`` (exit status 1).
"""

from __future__ import annotations

import argparse
import importlib
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

__all__ = ["STUDIES", "Study", "StudyUsageError", "build_parser", "get_study", "run_study", "script_main"]


class StudyUsageError(Exception):
    """A bad option of a study's command line, found by the study (a setting out of range, an option it cannot
    use): its parser refuses it, as it refuses an option it cannot parse."""


@dataclass(frozen=True)
class Study:
    """A study's command line: ``add_arguments(parser)`` adds its options, ``run(args)`` runs it on the parsed
    options, prints its output lines and returns its result (an ``int`` is the exit status)."""

    description: str
    add_arguments: Callable[[argparse.ArgumentParser], None]
    run: Callable[[argparse.Namespace], Any]


#: study name -> (the module of this package defining it, the one line ``ogm-ppl study --help`` shows), in the
#: order of that listing
STUDIES: dict[str, tuple[str, str]] = {
    "table_3_1": ("toys", "Table 3.1: summed KL of each mapping algorithm to the exact posterior, 1D datasets"),
    "vi_vs_exact_1d": ("toys", "VI against the exact posterior on the 1D toy: summed KL of marginals and time"),
    "vi_vs_mcmc": ("toys", "summed KL to the exact posterior against wall-clock time for every method"),
    "thesis_border_update": ("toys", "how far the thesis's border update (5.2.3) is from its posterior"),
    "fit_delta_setting": ("toys", "fit update terms Delta for one sensor setting, compared on held-out data"),
    "prior_stats": ("priors", "the patch statistics of the prior tables per corpus (5.2.2-5.2.3)"),
    "prior_occupancy": ("priors", "each prior's own occupied share in a region with no readings, vs its corpus's"),
    "border_chain_probe": ("priors", "prior mass and likelihood of a border-prior Gibbs chain, sweep by sweep"),
    "path_free": ("priors", "P(path free): the exact joint answer against the product of marginals, by prior"),
    "amortised_guide_eval": ("guides", "the amortised guide against Gibbs with the same prior and against p21 OGM"),
    "guide_limits": ("guides", "what limits a corpus guide on unseen cells: its calibration or what it tells apart"),
    "unseen_by_distance": ("guides", "a method's NLL on unseen cells by distance to the nearest reached cell"),
    "table_6_4_errors": ("maps", "where a Table 6.4 run's errors lie: observed or never-observed cells"),
    "touched_errors": ("maps", "where maps' errors on the touched cells lie, against the benchmark's walls"),
    "unobserved_marginals": ("maps", "mean marginal of the never-observed cells per algorithm and dataset"),
    "map_all_logs": ("maps", "map every shipped CARMEN log with ogm-ppl map; times and sizes"),
    "log_plans": ("maps", "floor plans of the real logs' buildings, cleaned from the maps of all their readings"),
    "active_routes": ("active", "where an active experiment's rules send the robot: step lengths, coverage gains"),
    "active_choice_probe": ("active", "information gain beside expected newly observed cells at every stop"),
    "tune_distance_offset": ("active", "choose the distance offset d_0 of the per-metre rules on validation plans"),
}


def get_study(name: str) -> Study:
    """The :class:`Study` named ``name`` (a key of :data:`STUDIES`)."""
    module = importlib.import_module(f"{__name__}.{STUDIES[name][0]}")
    return module.STUDIES[name]


def build_parser(
    name: str,
    prog: str,
    parser_class: type[argparse.ArgumentParser] = argparse.ArgumentParser,
    defaults: Mapping[str, Any] | None = None,
) -> argparse.ArgumentParser:
    """The argument parser of study ``name``: its summary and description, its options (``defaults`` replaces
    some of their defaults), ``prog`` as the program named in usage and errors."""
    study = get_study(name)
    parser = parser_class(
        prog=prog,
        description=f"{STUDIES[name][1][0].upper()}{STUDIES[name][1][1:]}.\n\n{study.description}",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    study.add_arguments(parser)
    if defaults:
        parser.set_defaults(**defaults)
    return parser


def input_errors() -> tuple[type[Exception], ...]:
    """The typed errors of the studies' inputs (printed as one message)."""
    from ogm_ppl.calibration import USER_ERRORS
    from ogm_ppl.studies.errors import STUDY_ERRORS

    return (*STUDY_ERRORS, *USER_ERRORS)


def run_study(name: str, parser: argparse.ArgumentParser, argv: list[str] | None) -> Any:
    """Parse ``argv`` with ``parser`` (from :func:`build_parser`) and run study ``name``; a setting refused by the
    study (:class:`StudyUsageError`, a study's or a fit's option error, a calibration setting) goes to
    ``parser.error``. Returns what the study's ``run`` returns."""
    args = parser.parse_args(argv)
    try:
        return get_study(name).run(args)
    except StudyUsageError as e:
        parser.error(str(e))
    except ValueError as e:
        from ogm_ppl.calibration import SettingsError
        from ogm_ppl.learn import FitOptionError
        from ogm_ppl.studies.errors import StudyOptionError

        if isinstance(e, SettingsError):
            parser.error(f"{e.flag}: {e.reason}")
        if isinstance(e, (StudyOptionError, FitOptionError)):
            parser.error(str(e))
        raise


def script_main(name: str, argv: list[str] | None, prog: str, **defaults: Any) -> Any:
    """A script's ``main(argv)``: study ``name``'s command line named ``prog``, ``defaults`` replacing some of its
    defaults (paths relative to the checkout); a bad input exits with ``prog: message`` (status 1)."""
    parser = build_parser(name, prog, defaults=defaults)
    try:
        return run_study(name, parser, argv)
    except input_errors() as e:
        raise SystemExit(f"{prog}: {e}") from None
