"""Command line ``ogm-ppl`` (also ``python -m ogm_ppl``): map a laser log, simulate or convert a dataset.

Subcommands (``ogm-ppl SUBCOMMAND --help`` lists every option):

``map INPUT --out DIR``
    Occupancy grid map of a CARMEN log (plain or gzip), a ROS bag (ROS 1 ``.bag``, a ROS 2 bag folder or
    its ``.db3`` / ``.mcap``: ``--scan-topic T`` and ``--pose-topic P`` or ``--tf``) or an ogm_ppl dataset
    file (``.npz``); told apart by their magic bytes. Writes ``map.npz`` (probabilities, observed mask, grid, settings),
    ``map.png`` (thesis colour scale, one pixel per cell, unknown cells grey), a ROS ``map_server`` map in
    ``ros/`` (``map.yaml`` + ``map.pgm`` + the exact-probability sidecar ``map.npz``, which would clash with
    ours beside it), ``report.json`` and ``report.md``. ``--method NAME`` is any registered map method
    (:mod:`ogm_ppl.methods`: ``ogm``, ``p21``, ``elfes``, ``gibbs``, ``patch``, ``vi``, ...), its
    parameters set by ``--param KEY=VALUE`` or the flags mapped onto them (``--delta``, ``--prior``,
    ``--lambda``, ``--sigma``, ``--sweeps``, ``--warmup``, ``--patch``). A sampling method's chains
    checkpoint into ``DIR/.checkpoints`` every ``checkpoint_every`` sweeps and on Ctrl-C; the same command
    resumes them (bit for bit), and the folder is removed once the map is written.
``methods [NAME]``
    The registered map methods, one line each, with their parameters (``NAME``: that method only).
``simulate --map KIND|PNG --out FILE.npz``
    A stop-and-scan dataset (Section 6.1) on a generated ground-truth map or a PNG floor plan.
``convert LOG|BAG --out FILE.npz``
    A CARMEN log or a ROS bag as a dataset file.
``info LOG|BAG|DATASET``
    What a log, bag or dataset file holds: scans, beams per scan, angular increment, field of view, range
    limits, the no-return rule and its beams, extent, duration, scan and pose rates (``--json``).
``experiment SPEC``
    An experiment spec (TOML, :mod:`ogm_ppl.experiment`).
``run --out DIR``
    The headline experiment (what ``make run`` calls): :func:`ogm_ppl.experiment.headline.run_headline`.
``calibrate [--quick] [--out DIR]``
    Priors and guides scored as predictors of unseen cells on held-out maps (thesis 5.2):
    :func:`ogm_ppl.calibration.calibrate`.
``train-guide --corpus C ... | --plan-files PATH ... --out FILE.npz``
    An amortised corpus guide for one's own sensor, trained on corpora's training plans or plan files of
    one's own (:func:`ogm_ppl.learn.train_corpus_guide`); checkpoints, and the same command resumes.
``corpus-stats NAME [--out DIR]``
    Statistics of a floor-plan corpus as rasterised (plans, buildings, splits, cells, known and occupied share,
    wall thickness in cells) as JSON, and a figure of a few plans beside their sources
    (:mod:`ogm_ppl.datasets.floorplans.stats`).

Each subcommand is a module of this package (:data:`COMMANDS`) with ``add_parser(sub)`` and ``run(args)``;
a new workflow adds a module and one entry.

Bad arguments and bad input files give one line ``ogm-ppl: error: ...`` on stderr and exit status 2
(``--traceback`` shows the Python traceback instead).
"""

from __future__ import annotations

import argparse
import importlib
import sys

from ogm_ppl.cli._common import CLIError, _inputs_of, _one_line, _Parser, _refuse_out_over_inputs, _version
from ogm_ppl.cli._map_files import load_map, save_map_png
from ogm_ppl.methods import MethodModuleError

__all__ = ["COMMANDS", "CLIError", "build_parser", "load_map", "main", "save_map_png"]

#: the subcommands, in the order ``--help`` lists them: each is the module ``ogm_ppl.cli.<module>`` with
#: ``add_parser(sub)`` (adds the subcommand's parser to ``sub``) and ``run(args) -> int`` (the exit status)
COMMANDS: dict[str, str] = {
    "map": "map",
    "methods": "methods",
    "simulate": "simulate",
    "convert": "convert",
    "info": "info",
    "fit-prior": "fit_prior",
    "experiment": "experiment",
    "run": "run",
    "calibrate": "calibrate",
    "train-guide": "train_guide",
    "corpus-stats": "corpus_stats",
}


def _command(name: str):
    return importlib.import_module(f"ogm_ppl.cli.{COMMANDS[name]}")


def build_parser() -> argparse.ArgumentParser:
    """The ``ogm-ppl`` argument parser: one subparser per entry of :data:`COMMANDS`."""
    parser = _Parser(prog="ogm-ppl", description=__doc__.splitlines()[0])
    parser.add_argument(
        "--version", action="version", version=f"ogm-ppl {_version()}", help="print the version and exit"
    )
    parser.add_argument(
        "--traceback",
        action="store_true",
        help="on an error, show the Python traceback instead of one line (for bug reports)",
    )
    sub = parser.add_subparsers(
        dest="command",
        required=True,
        metavar="COMMAND",
        help=f"{', '.join(COMMANDS)} (COMMAND --help for its options)",
    )
    for name in COMMANDS:
        _command(name).add_parser(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point of ``ogm-ppl`` / ``python -m ogm_ppl``; returns the exit status (0 ok, 2 error)."""
    from ogm_ppl.datasets import CarmenFormatError, DatasetFileError
    from ogm_ppl.rosmap import RosMapError

    argv = sys.argv[1:] if argv is None else list(argv)
    show_tb = "--traceback" in argv
    try:
        try:
            args = build_parser().parse_args(argv)
        except SystemExit as e:  # --help, --version
            return int(e.code or 0) if not isinstance(e.code, str) else 2
        _refuse_out_over_inputs(getattr(args, "out", None), _inputs_of(args))
        return int(_command(args.command).run(args))
    except (
        CLIError,
        CarmenFormatError,
        DatasetFileError,
        RosMapError,
        MethodModuleError,
        ValueError,
        OSError,
        MemoryError,
    ) as e:
        if show_tb:
            raise
        if isinstance(e, MemoryError):
            msg = _one_line(e) if str(e) else "out of memory; use a coarser --resolution or fewer scans (--pose-step)"
        else:
            msg = _one_line(e)
        print(f"ogm-ppl: error: {msg}", file=sys.stderr)
        return 2
    except KeyboardInterrupt as e:
        if show_tb:
            raise
        print(f"ogm-ppl: interrupted{'; ' + str(e) if str(e) else ''}", file=sys.stderr)
        return 130
