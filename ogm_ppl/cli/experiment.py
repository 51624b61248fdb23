"""``ogm-ppl experiment SPEC``: an experiment spec (TOML, :mod:`ogm_ppl.experiment`) on dask."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    pass
from ogm_ppl.cli._common import (
    CLIError,
    _one_line,
    _pos_int,
    _prepare_out_dir,
)


def add_parser(sub) -> None:
    """The ``experiment`` subcommand's options."""
    e = sub.add_parser(
        "experiment",
        help="run an experiment spec (TOML): datasets x algorithms x chains",
        description="Run an experiment spec (ogm_ppl.experiment): every dataset x algorithm x "
        "chain is a dask task; writes maps, metrics.json/.md and figures.",
    )
    e.add_argument("spec", type=Path, help="the spec file (TOML; its keys: docs/guide/experiments.md)")
    e.add_argument("--out", type=Path, default=None, help="output directory (default out/experiments/<name>)")
    e.add_argument(
        "--scheduler",
        default=None,
        metavar="ADDR",
        help="'serial' (no dask), a dask scheduler address tcp://..., or none for a LocalCluster",
    )
    e.add_argument("--workers", type=_pos_int, default=None, help="LocalCluster workers (default: one per core)")
    e.add_argument("--no-resume", action="store_true", help="rerun tasks that are already done")
    e.add_argument("--quiet", action="store_true", help="no progress output")
    e.add_argument(
        "--algorithms",
        nargs="+",
        metavar="NAME",
        default=None,
        help="run only these algorithms (the methods of an active spec) of the spec (a later run into the same "
        "--out resumes the rest)",
    )


def run(args) -> int:
    """``ogm-ppl experiment SPEC``: 0 when every task finished, 1 when some failed (what finished is kept)."""
    from ogm_ppl.experiment import ExperimentError, SpecError, load_spec, run_experiment

    try:
        spec = load_spec(args.spec)
        if args.algorithms:
            spec = spec.only(args.algorithms)
    except SpecError as e:
        raise CLIError(str(e)) from None
    out = args.out if args.out is not None else Path("out") / "experiments" / spec.name
    _prepare_out_dir(Path(out))
    try:
        r = run_experiment(
            spec,
            out,
            scheduler=args.scheduler,
            workers=args.workers,
            resume=not args.no_resume,
            progress=not args.quiet,  # a bar on a terminal, plain lines in a log
        )
    except ExperimentError as e:
        print(f"ogm-ppl: error: {_one_line(e)}", file=sys.stderr)
        return 1
    except KeyboardInterrupt as e:
        raise KeyboardInterrupt(
            f"finished tasks and the samplers' checkpoints are kept in {out}: the same command resumes from them"
        ) from e
    print(r.table())
    print(f"{len(r.executed)} tasks run, {len(r.skipped)} found done, {r.seconds:.1f} s; results in {out}")
    return 0
