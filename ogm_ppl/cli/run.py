"""``ogm-ppl run --out DIR``: the headline experiment (what ``make run`` calls)."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    pass
from ogm_ppl.cli._common import (
    _pos_int,
    _prepare_out_dir,
    _seed,
)


def add_parser(sub) -> None:
    """The ``run`` subcommand's options."""
    p = sub.add_parser("run", help="the headline experiment: maps, figures and a report")
    p.add_argument("--out", type=Path, default=Path("out"), help="output directory (default out)")
    p.add_argument("--seed", type=_seed, default=0, help="random seed of the simulated part (default 0)")
    p.add_argument(
        "--log",
        type=Path,
        default=None,
        help="the Intel Lab log (default: intel-lab/intel-corrected.log.gz under $OGM_PPL_DATA or the "
        "shared data folder)",
    )
    p.add_argument("--quick", action="store_true", help="a small version (10 cm, 10 %% of poses, 6 sweeps)")
    p.add_argument("--scheduler", default=None, help="'serial', a dask scheduler address, or none for a LocalCluster")
    p.add_argument("--workers", type=_pos_int, default=None, help="LocalCluster workers (default: one per core)")


def run(args) -> int:
    """``ogm-ppl run``: the headline experiment; prints its report."""
    from ogm_ppl.experiment.headline import run_headline

    _prepare_out_dir(args.out)
    run_headline(
        args.out,
        seed=args.seed,
        log=args.log,
        quick=args.quick,
        scheduler=args.scheduler,
        workers=args.workers,
        progress=True,  # a bar on a terminal, plain lines in a log
    )
    print((args.out / "report.md").read_text())
    return 0
