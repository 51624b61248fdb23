"""``ogm-ppl study NAME [options]``: run one of the studies of :mod:`ogm_ppl.studies`, the computations behind the
thesis's tables and the library's own studies, with its own options (``ogm-ppl study NAME --help``).

``ogm-ppl study --help`` lists the studies, one line each. A study writes into the folder or file its options
name and prints what it found; its command line is defined in :mod:`ogm_ppl.cli._studies` (the scripts of the
repository's ``experiments/`` call the same code).
"""

from __future__ import annotations

import argparse

from ogm_ppl.cli._common import _Parser
from ogm_ppl.cli._studies import STUDIES, build_parser, run_study


def _listing() -> str:
    width = max(map(len, STUDIES))
    return "studies:\n" + "\n".join(f"  {name:<{width}}  {line}" for name, (_, line) in STUDIES.items())


def add_parser(sub) -> None:
    """The ``study`` subcommand: a study's name and its options (parsed by the study's own parser)."""
    p = sub.add_parser(
        "study",
        help="run a study of the thesis's tables or the library's own (ogm-ppl study --help lists them)",
        description="Run a study: the computation behind a table of the thesis or a study of the library, with its "
        "own options (ogm-ppl study NAME --help).",
        epilog=_listing(),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("study", choices=list(STUDIES), metavar="NAME", help="the study (listed below)")
    p.add_argument("options", nargs=argparse.REMAINDER, help="the study's options (ogm-ppl study NAME --help)")


def run(args: argparse.Namespace) -> int:
    """``ogm-ppl study NAME ...``: parse the study's options and run it; the exit status is the study's (0 unless
    it says otherwise)."""
    parser = build_parser(args.study, f"ogm-ppl study {args.study}", parser_class=_Parser)
    try:
        result = run_study(args.study, parser, args.options)
    except SystemExit as e:  # --help
        return int(e.code or 0) if not isinstance(e.code, str) else 2
    return result if isinstance(result, int) else 0
