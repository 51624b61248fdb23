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
``calibrate [--quick] --out DIR``
    Priors and guides scored as predictors of unseen cells on held-out maps (thesis 5.2):
    :func:`ogm_ppl.calibration.calibrate`.

Bad arguments and bad input files give one line ``ogm-ppl: error: ...`` on stderr and exit status 2
(``--traceback`` shows the Python traceback instead).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import os
import shutil
import sys
import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ogm_ppl.datasets.mapgen import KINDS
from ogm_ppl.grid import MAX_CELLS, Grid
from ogm_ppl.io import StagedFolder, atomic_write, atomic_write_text, writable_folder
from ogm_ppl.methods import (
    MapProblem,
    MethodModuleError,
    ParamError,
    RunContext,
    get_method,
    method_names,
    methods,
)

if TYPE_CHECKING:
    from ogm_ppl.datasets.carmen import CarmenLog
    from ogm_ppl.datasets.rosbag import BagLog
    from ogm_ppl.methods import MapMethod
    from ogm_ppl.scans import Scans

_PNG_UNKNOWN = (217, 217, 217)  # the light grey of viz.plot_map for unknown cells
MAP_FORMAT = "ogm_ppl.map"
MAP_FORMAT_VERSION = 1
#: flags of ``ogm-ppl map`` that set a method parameter: flag -> (parameter, argparse dest)
METHOD_FLAGS = {
    "--delta": ("delta", "delta"),
    "--prior": ("prior", "prior"),
    "--lambda": ("lam", "lam"),
    "--sigma": ("sigma_cells", "sigma"),
    "--sensor": ("sensor", "sensor"),
    "--sweeps": ("sweeps", "sweeps"),
    "--warmup": ("burn_in", "warmup"),
    "--patch": ("patch", "patch"),
    "--threads": ("threads", "threads"),
}
#: the command line's own defaults (``--help`` states them): sweeps, burn-in = sweeps // 10, and the
#: thesis's cell prior 0.234 for the prior "independent"
CLI_SWEEPS, CLI_LAMBDA = 200, 0.234


class CLIError(Exception):
    """A user error: printed as one line ``ogm-ppl: error: ...``, exit status 2."""


class _Parser(argparse.ArgumentParser):
    """argparse that raises :class:`CLIError` instead of printing usage and exiting."""

    def error(self, message: str):
        raise CLIError(message)


def _version() -> str:
    from importlib import metadata

    try:
        return metadata.version("ogm_ppl")
    except metadata.PackageNotFoundError:  # pragma: no cover - running from a source tree
        from ogm_ppl import __version__

        return __version__


# ---------------------------------------------------------------------------------- argument types
def _number(kind, lo=None, lo_open=False, hi=None, hi_open=False):
    """An argparse type: ``kind`` (int/float), finite, within ``[lo, hi]`` (open ends as flagged)."""

    def parse(text: str):
        try:
            v = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(
                f"expected {'a whole number' if kind is int else 'a number'}, got {text!r}"
            ) from None
        if kind is float and not math.isfinite(v):
            raise argparse.ArgumentTypeError(f"must be finite, got {text!r}")
        if lo is not None and (v <= lo if lo_open else v < lo):
            raise argparse.ArgumentTypeError(f"must be {'>' if lo_open else '>='} {lo}, got {text}")
        if hi is not None and (v >= hi if hi_open else v > hi):
            raise argparse.ArgumentTypeError(f"must be {'<' if hi_open else '<='} {hi}, got {text}")
        return v

    parse.__name__ = kind.__name__  # argparse names the type in "invalid <name> value" messages
    return parse


_pos_float = _number(float, 0, True)
_nonneg_float = _number(float, 0)
_pos_int = _number(int, 1)
_nonneg_int = _number(int, 0)
_fraction = _number(float, 0, True, 1)
_probability = _number(float, 0, True, 1, True)
_finite = _number(float)


def _add_reader_options(p: argparse.ArgumentParser, carmen_only: bool) -> None:
    note = " (CARMEN logs and ROS bags)" if carmen_only else ""
    p.add_argument(
        "--lenient",
        action="store_true",
        help="skip malformed log lines or bag messages (listed in the report) instead of stopping at the "
        "first one; by default a malformed line is an error naming file, line (bag: topic, message) and "
        "field" + note,
    )
    p.add_argument(
        "--max-usable-range",
        type=_pos_float,
        metavar="R",
        help="drop readings at or beyond R metres (the Intel protocol of thesis Section 6.2 is "
        "20); default: keep every reading" + note,
    )
    p.add_argument(
        "--no-return",
        choices=("drop", "max"),
        help="what a no-return sentinel reading becomes: 'drop' (invalid beam, the default, as "
        "in the thesis) or 'max' (a max-range reading that clears the cells it crosses)" + note,
    )
    g = p.add_mutually_exclusive_group()
    g.add_argument("--pose-step", type=_pos_int, default=1, metavar="K", help="keep every K-th scan (default 1: all)")
    g.add_argument(
        "--pose-fraction",
        type=_fraction,
        metavar="F",
        help="keep an evenly spaced fraction F in (0, 1] of the scans (Table 6.5 uses 0.1)",
    )
    p.add_argument(
        "--beam-step",
        type=_pos_int,
        default=1,
        metavar="K",
        help="keep every K-th beam of each scan (default 1: all; 2 halves the beams)",
    )


def _add_bag_options(p: argparse.ArgumentParser, required_pose: bool = True) -> None:
    g = p.add_argument_group("ROS bags (ogm_ppl.datasets.read_bag)")
    g.add_argument(
        "--scan-topic",
        metavar="T",
        help="the sensor_msgs/LaserScan topic (default: the bag's only LaserScan topic)",
    )
    src = g.add_mutually_exclusive_group()
    src.add_argument(
        "--pose-topic",
        metavar="P",
        help="poses from a nav_msgs/Odometry, geometry_msgs/PoseStamped or PoseWithCovarianceStamped topic"
        + ("" if required_pose else " (default: the bag's only pose topic, else /tf if present)"),
    )
    src.add_argument(
        "--tf",
        action="store_true",
        help="poses from /tf + /tf_static: --map-frame -> ... -> the scans' frame (laser mounting included)",
    )
    g.add_argument("--map-frame", default="map", metavar="F", help="world frame of --tf (default map)")
    g.add_argument(
        "--laser-offset",
        type=_finite,
        nargs=3,
        metavar=("X", "Y", "YAW"),
        help="the laser in the robot frame of --pose-topic (metres, radians; default 0 0 0)",
    )
    g.add_argument(
        "--pose-tolerance",
        type=_nonneg_float,
        default=0.1,
        metavar="S",
        help="drop scans more than S seconds from the pose samples around them (default 0.1; counted)",
    )


_BAG_FLAGS = {
    "--scan-topic": "scan_topic",
    "--pose-topic": "pose_topic",
    "--tf": "tf",
    "--laser-offset": "laser_offset",
}


def build_parser() -> argparse.ArgumentParser:
    """The ``ogm-ppl`` argument parser (subcommands ``map``, ``simulate``, ``convert``, ``run``)."""
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
        help="map, methods, simulate, convert, info, experiment, run or calibrate (COMMAND --help for its options)",
    )

    # --------------------------------------------------------------------------------- map
    m = sub.add_parser(
        "map",
        help="occupancy grid map of a CARMEN log, a ROS bag or a dataset file",
        description="Map INPUT (a CARMEN log, plain or gzip, a ROS 1 or ROS 2 bag, or an ogm_ppl dataset .npz) into "
        "DIR: map.npz, map.png, ros/map.yaml + ros/map.pgm (+ sidecar), "
        "report.json, report.md. A sampling method (gibbs, patch, ...) checkpoints its chains in DIR/.checkpoints "
        "(every checkpoint_every sweeps, and on Ctrl-C): rerunning the same command resumes them.",
    )
    m.add_argument(
        "input",
        type=Path,
        metavar="INPUT",
        help="a CARMEN log (.log / .log.gz), a ROS bag (.bag, a ROS 2 bag folder, .db3, .mcap) or a dataset .npz",
    )
    m.add_argument("--out", type=Path, required=True, metavar="DIR", help="output directory (created)")
    m.add_argument(
        "--resolution",
        type=_pos_float,
        metavar="M",
        help="cell size in metres (default 0.05; for a dataset file with a grid, its resolution)",
    )
    ext = m.add_mutually_exclusive_group()
    ext.add_argument(
        "--size",
        type=_pos_int,
        nargs=2,
        metavar=("W", "H"),
        help="grid of W columns x H rows cells with its lower-left corner at --origin (default "
        "origin 0 0); every pose must lie inside",
    )
    ext.add_argument(
        "--auto-extent",
        action="store_true",
        help="(default) a grid covering every pose and hit end point plus --margin; for a dataset "
        "file with a grid and no --resolution/--margin/--origin, that grid",
    )
    m.add_argument(
        "--origin",
        type=_finite,
        nargs=2,
        metavar=("X", "Y"),
        help="world coordinates (metres) of the grid's lower-left corner",
    )
    m.add_argument(
        "--crop",
        action="store_true",
        help="with --size: map the part of the data the grid covers, keeping the scans whose pose lies on "
        "it (beams reaching beyond it are clipped at its edge) instead of refusing the others",
    )
    m.add_argument(
        "--scans",
        type=_scan_range,
        metavar="A:B",
        help="map the scans A to B - 1 of the input (0-based, A < B, either end may be left open: 100:400, :400, "
        "100:; an end past the last scan stops there), counted before --pose-step / --pose-fraction thin them; "
        "the report lists what each step kept",
    )
    m.add_argument(
        "--margin",
        type=_nonneg_float,
        metavar="M",
        help="metres added on every side of the automatic extent (default 1.0)",
    )
    m.add_argument(
        "--max-cells",
        type=_pos_int,
        default=MAX_CELLS,
        metavar="N",
        help=f"refuse grids of more than N cells (default {MAX_CELLS:,})",
    )
    m.add_argument(
        "--method",
        default="ogm",
        metavar="NAME",
        help="map method (default ogm), any registered one (ogm-ppl methods lists them with their "
        "parameters): " + ", ".join(method_names()),
    )
    m.add_argument(
        "--param",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="set a parameter of the method (repeatable), e.g. --param scan=random; 'ogm-ppl methods NAME' lists them",
    )
    m.add_argument(
        "--delta",
        metavar="NAME",
        help="parameter delta: the update term of the log-odds methods, any name delta_by_name "
        "knows (haehnel, elfes_thesis, p21_thesis, p21, moravec_opt, ...); default: haehnel "
        "for ogm, p21 for p21, elfes_thesis for elfes",
    )
    m.add_argument(
        "--prior",
        metavar="NAME",
        help="parameter prior of the model-based methods (gibbs, patch, ...; of ogm: the cells' "
        "prior occupancy, a number): 'independent' (each "
        "cell occupied with probability --lambda, the default) or a learned prior "
        "KIND:CORPUS (ogm_ppl.priors.prior_by_name), e.g. mrf:houseexpo, patch3:houseexpo, "
        "border:houseexpo, border1:houseexpo",
    )
    m.add_argument(
        "--lambda",
        dest="lam",
        type=_probability,
        metavar="P",
        help=f"parameter lam: cell prior occupancy of the independent prior (default {CLI_LAMBDA}, the thesis's value)",
    )
    m.add_argument(
        "--sigma",
        type=_pos_float,
        metavar="CELLS",
        help="parameter sigma_cells: range noise of the sensor model in cells (the Gaussian range model's "
        "standard deviation) "
        "(default: the dataset's simulation sigma if recorded, else 1.0 cell, about the "
        "scatter of a corrected real log at 5 cm)",
    )
    m.add_argument(
        "--sensor",
        metavar="NAME",
        help="parameter sensor of the model-based methods: the forward sensor model by name, KIND or "
        "KIND:KEY=VALUE,... (ogm_ppl.sensors.sensor_by_name; default gaussian, the Gaussian range model of "
        "--sigma; a kind of your own registered with register_sensor in a module named in $OGM_PPL_METHODS, "
        "its factory's keyword parameters its options)",
    )
    m.add_argument(
        "--threads",
        type=_pos_int,
        metavar="N",
        help="parameter threads of gibbs: chromatic tile sweeps on N of numba's threads (exact; one chain "
        "whatever N, another than the serial kernel's; priors with a compiled face)",
    )
    m.add_argument(
        "--sweeps",
        type=_pos_int,
        metavar="N",
        help=f"parameter sweeps: MCMC sweeps counted in the marginals (default {CLI_SWEEPS})",
    )
    m.add_argument(
        "--warmup",
        type=_nonneg_int,
        metavar="N",
        help="parameter burn_in: MCMC sweeps run before counting (default: sweeps // 10)",
    )
    m.add_argument(
        "--patch",
        metavar="SHAPE",
        help="parameter patch: of gibbs (PatchGibbs instead of CellGibbs) and patch "
        "(default 3x3): HxW, an int L (a run of L cells), 'plus' or 'square'",
    )
    m.add_argument("--seed", type=_nonneg_int, default=0, metavar="S", help="random seed (>= 0, default 0)")
    m.add_argument(
        "--online",
        action="store_true",
        help="replay the scans one at a time into an online single-cell Gibbs chain (--method gibbs; "
        "ogm_ppl.inference.online): focused sweeps after each scan, then --warmup and --sweeps full sweeps",
    )
    m.add_argument(
        "--snapshots",
        type=_pos_int,
        metavar="K",
        help="with --online: also write snapshots.npz, the marginals after every K-th scan",
    )
    _add_reader_options(m, carmen_only=True)
    _add_bag_options(m)
    m.add_argument(
        "--thresholds",
        choices=("ros1", "nav2"),
        default="ros1",
        help="occupied/free thresholds of the ROS map: ros1 (0.65/0.196, default) or nav2 (0.65/0.25)",
    )
    m.add_argument(
        "--unobserved",
        choices=("unknown", "predict"),
        default="unknown",
        help="cells no ray reached, in map.png and the ROS map: unknown (grey / -1, default; what a planner "
        "should not drive into) or predict (drawn and thresholded from their probability, as every other cell: "
        "what a correlated prior predicts there). map.npz always holds every cell's probability",
    )

    # ---------------------------------------------------------------------------- simulate
    s = sub.add_parser(
        "simulate",
        help="a simulated stop-and-scan dataset (Section 6.1)",
        description="Simulate a stop-and-scan dataset (360 degree scans at the stops of a "
        "frontier-exploration route) on a ground-truth map and save it as a "
        "dataset file with the truth.",
    )
    s.add_argument(
        "--map",
        nargs="+",
        required=True,
        metavar="SPEC",
        help="ground truth: 'generated KIND' (or just KIND, or generated:KIND), KIND one of "
        f"{', '.join(KINDS)}; or a PNG floor plan (dark pixels < 128 are occupied)",
    )
    s.add_argument("--out", type=Path, required=True, metavar="FILE.npz", help="dataset file to write")
    s.add_argument(
        "--size",
        type=_number(int, 60),
        default=500,
        metavar="N",
        help="generated map of N x N cells (default 500 as in Fig. 5.9; at least 60; outer wall "
        "min(20, N // 4) cells thick)",
    )
    s.add_argument("--resolution", type=_pos_float, default=0.05, metavar="M", help="metres per cell (default 0.05)")
    s.add_argument(
        "--poses",
        type=_pos_int,
        metavar="N",
        help="at most N stops (default: explore until 95 %% of the free space is seen)",
    )
    s.add_argument("--beams", type=_pos_int, default=720, metavar="B", help="beams per 360 degree scan (default 720)")
    s.add_argument(
        "--max-range-cells",
        type=_pos_float,
        default=75.0,
        metavar="F",
        help="sensor maximum range in cells (default 75)",
    )
    s.add_argument(
        "--sigma", type=_nonneg_float, default=3.0, metavar="CELLS", help="Gaussian range noise in cells (default 3)"
    )
    s.add_argument("--seed", type=_nonneg_int, default=0, metavar="S", help="random seed (>= 0, default 0)")

    # ----------------------------------------------------------------------------- convert
    c = sub.add_parser(
        "convert",
        help="a CARMEN log or a ROS bag as a dataset file",
        description="Read a CARMEN log (plain or gzip) or a ROS bag and save its scans as a dataset file.",
    )
    c.add_argument("log", type=Path, metavar="LOG|BAG", help="the CARMEN log or ROS bag")
    c.add_argument("--out", type=Path, required=True, metavar="FILE.npz", help="dataset file to write")
    c.add_argument(
        "--resolution",
        type=_pos_float,
        metavar="M",
        help="also store a grid of this resolution covering the log (extent + 1 m margin)",
    )
    _add_reader_options(c, carmen_only=False)
    _add_bag_options(c)

    # -------------------------------------------------------------------------------- info
    i = sub.add_parser(
        "info",
        help="what a log, bag or dataset file holds",
        description="Scans, beams per scan, angular increment, field of view, range limits, the no-return "
        "rule and its beams, extent, duration, scan and pose rates of a CARMEN log, a ROS bag or a dataset "
        "file, as read with the given reader options.",
    )
    i.add_argument("input", type=Path, metavar="LOG|BAG|DATASET", help="a CARMEN log, a ROS bag or a dataset .npz")
    i.add_argument("--json", action="store_true", help="print JSON instead of lines")
    _add_reader_options(i, carmen_only=False)
    _add_bag_options(i, required_pose=False)

    # --------------------------------------------------------------------------------- methods
    ms = sub.add_parser(
        "methods",
        help="list the map methods and their parameters",
        description="List the registered map methods (ogm_ppl.methods): name, one line, and each parameter "
        "with its default, kind and meaning; then the prior and sensor kinds the parameters prior and sensor "
        "take (shipped and registered).",
    )
    ms.add_argument("name", nargs="?", metavar="NAME", help="show this method only")

    # --------------------------------------------------------------------------------- experiment
    e = sub.add_parser(
        "experiment",
        help="run an experiment spec (TOML): datasets x algorithms x chains",
        description="Run an experiment spec (ogm_ppl.experiment): every dataset x algorithm x "
        "chain is a dask task; writes maps, metrics.json/.md and figures.",
    )
    e.add_argument("spec", type=Path, help="the spec file (see experiments/specs/*.toml)")
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

    # --------------------------------------------------------------------------------- run
    run = sub.add_parser("run", help="the headline experiment: maps, figures and a report")
    run.add_argument("--out", type=Path, default=Path("out"), help="output directory (default out)")
    run.add_argument("--seed", type=_nonneg_int, default=0, help="random seed of the simulated part (default 0)")
    run.add_argument(
        "--log",
        type=Path,
        default=None,
        help="the Intel Lab log (default: intel-lab/intel-corrected.log.gz under $OGM_PPL_DATA or the "
        "shared data folder)",
    )
    run.add_argument("--quick", action="store_true", help="a small version (10 cm, 10 %% of poses, 6 sweeps)")
    run.add_argument("--scheduler", default=None, help="'serial', a dask scheduler address, or none for a LocalCluster")
    run.add_argument("--workers", type=_pos_int, default=None, help="LocalCluster workers (default: one per core)")

    # --------------------------------------------------------------------------------- calibrate
    from ogm_ppl.calibration import _command as calibrate_command

    calibrate_command.add_parser(sub)
    return parser


# --------------------------------------------------------------------------------------- helpers
def _progress() -> bool:
    """Progress bars only on an interactive stderr (never in pipes, logs or tests)."""
    try:
        return sys.stderr.isatty()
    except (AttributeError, ValueError):  # pragma: no cover
        return False


def _steps(total: int, desc: str):
    from tqdm.auto import tqdm

    return tqdm(total=total, desc=desc, unit="step", disable=not _progress(), leave=False)


def _check_input(path: Path) -> bytes:
    """The first bytes of ``path``; a clear error if it cannot be read."""
    if not path.exists():
        raise CLIError(f"{path}: no such file")
    if path.is_dir():
        raise CLIError(f"{path}: is a directory, not a log or dataset file")
    try:
        with open(path, "rb") as f:
            return f.read(4)
    except OSError as e:
        raise CLIError(f"{path}: cannot read ({e.strerror or e})") from None


def _image_kind(magic: bytes) -> str | None:
    """``"PNG"``, ``"JPEG"``, ``"PGM"`` (or another netpbm format), ``"GIF"``, ``"TIFF"`` or ``"BMP"`` from a
    file's first bytes; ``None`` for anything else."""
    if magic.startswith(b"\x89PNG"):
        return "PNG"
    if magic.startswith(b"\xff\xd8"):
        return "JPEG"
    if magic[:1] == b"P" and magic[1:2] in b"123456" and magic[2:3] in b" \t\r\n#":
        return "PGM" if magic[1:2] in b"25" else "netpbm"
    if magic.startswith(b"GIF8"):
        return "GIF"
    if magic[:4] in (b"II*\x00", b"MM\x00*"):
        return "TIFF"
    if magic.startswith(b"BM"):
        return "BMP"
    return None


def _check_writable(directory: Path, out: Path) -> None:
    """Create ``directory`` and write and remove a file there, naming ``--out`` on failure."""
    try:
        writable_folder(directory)
    except OSError as e:
        raise CLIError(f"--out {out}: cannot write there ({e.strerror or e})") from None


def _prepare_out_dir(out: Path) -> None:
    """Create ``out`` and make sure a file can be written there (before any long computation)."""
    if out.exists() and not out.is_dir():
        raise CLIError(f"--out {out}: exists and is not a directory")
    _check_writable(out, out)


def _prepare_out_file(out: Path) -> None:
    """Make sure ``out``'s directory exists and takes a file (before any long computation)."""
    if out.is_dir():
        raise CLIError(f"--out {out}: is a directory; give a file name such as data.npz")
    parent = out.parent
    if parent.exists() and not parent.is_dir():
        raise CLIError(f"--out {out}: {parent} is not a directory")
    _check_writable(parent, out)


def _reader_kwargs(args) -> dict:
    stretch = getattr(args, "scans", None) is not None  # thinned after the stretch is cut (_select_scans)
    return dict(
        strict=not args.lenient,
        max_usable_range=args.max_usable_range,
        no_return=args.no_return or "drop",
        pose_step=1 if stretch else args.pose_step,
        pose_fraction=None if stretch else args.pose_fraction,
        beam_step=args.beam_step,
    )


def _select_scans(args, inp: _Input) -> _Input:
    """``--scans A:B``: the stretch of the scans as read (the reader did not thin them), then thinned by
    ``--pose-step`` / ``--pose-fraction``; :attr:`_Input.selection` records each step and its count."""
    if getattr(args, "scans", None) is None:
        return inp
    lo, hi = args.scans
    S = inp.scans.num_scans
    given = f"{'' if lo is None else lo}:{'' if hi is None else hi}"
    a, b = lo or 0, S if hi is None else min(hi, S)
    if a >= b:
        raise CLIError(f"--scans {given}: {inp.path} holds {S} scans (0..{S - 1})")
    scans = inp.scans.select(np.arange(a, b))
    steps = [f"{S:,} read", f"--scans {given}: {scans.num_scans:,}"]
    if args.pose_step != 1 or args.pose_fraction is not None:
        scans = scans.subsample(args.pose_step, 1, args.pose_fraction)
        thin = f"--pose-step {args.pose_step}" if args.pose_step != 1 else f"--pose-fraction {args.pose_fraction:g}"
        steps.append(f"{thin}: {scans.num_scans:,}")
    return dataclasses.replace(inp, scans=scans, selection=tuple(steps))


def _jsonable(x):
    """Paths, numpy scalars and tuples as plain JSON values."""
    if isinstance(x, dict):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    if isinstance(x, Path):
        return str(x)
    if isinstance(x, np.generic):
        return x.item()
    if isinstance(x, float) and not math.isfinite(x):
        return None
    return x


def _scan_range(text: str) -> tuple[int | None, int | None]:
    """``A:B``, ``A:`` or ``:B`` (non-negative integers, ``A < B``) as ``(A, B)`` with ``None`` for an open end."""
    a, colon, b = text.partition(":")
    try:
        if not colon:
            raise ValueError
        lo, hi = (int(a) if a.strip() else None), (int(b) if b.strip() else None)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected A:B (scan indices, e.g. 100:400), got {text!r}") from None
    if (lo is not None and lo < 0) or (hi is not None and hi < 0):
        raise argparse.ArgumentTypeError(f"scan indices must be >= 0, got {text!r}")
    if lo is not None and hi is not None and hi <= lo:
        raise argparse.ArgumentTypeError(f"the range {text!r} holds no scan (B must exceed A)")
    return lo, hi


def _check_cells(rows: int, cols: int, limit: int) -> None:
    n = rows * cols
    if n > limit:
        raise CLIError(
            f"the grid would have {cols} x {rows} = {n:,} cells, more than the limit of {limit:,} "
            "(--max-cells); use a coarser --resolution, a smaller --size or a larger --max-cells"
        )


@dataclass
class _Input:
    kind: str  # "carmen", "bag" or "dataset"
    path: Path
    scans: Scans
    grid: Grid | None = None  # the dataset's own grid
    truth: np.ndarray | None = None
    log: CarmenLog | None = None
    settings: dict = field(default_factory=dict)
    bag: BagLog | None = None
    selection: tuple[str, ...] = ()  # what --scans / --crop (and thinning after --scans) kept, step by step


def _is_bag(path: Path) -> bool:
    from ogm_ppl.datasets.rosbag import bag_kind

    return path.exists() and bag_kind(path) is not None


def _bag_kwargs(args, path: Path, pose_required: bool = True) -> dict:
    """read_bag's arguments from the bag options: the scan topic (the only LaserScan topic by default)
    and one pose source; a clear error naming the flag otherwise."""
    from ogm_ppl.datasets.rosbag import bag_info

    info = None
    scan = args.scan_topic
    if scan is None or (args.pose_topic is None and not args.tf):
        info = bag_info(path, laser=False, strict=not args.lenient)
    if scan is None:
        assert info is not None
        lasers = info["laser_topics"]
        if len(lasers) != 1:
            raise CLIError(
                f"{path}: give --scan-topic; the bag has {len(lasers)} LaserScan topics"
                + (f" ({', '.join(lasers)})" if lasers else "")
            )
        scan = lasers[0]
    pose, tf = args.pose_topic, bool(args.tf)
    if pose is None and not tf:
        assert info is not None
        if pose_required:
            cand = ", ".join(info["pose_topics"]) or "none"
            raise CLIError(
                f"{path}: give --pose-topic P (pose topics in the bag: {cand}) or --tf"
                + (" (the bag has /tf)" if info["tf"] else " (the bag has no /tf)")
            )
        if len(info["pose_topics"]) == 1:
            pose = info["pose_topics"][0]
        elif info["tf"]:
            tf = True
        else:
            return {"scan_topic": scan}
    if tf and args.laser_offset is not None:
        raise CLIError("--laser-offset applies to --pose-topic; with --tf the mounting comes from /tf_static")
    kw = dict(scan_topic=scan, pose_topic=pose, tf=tf, pose_tolerance=args.pose_tolerance, **_reader_kwargs(args))
    if tf:
        kw["map_frame"] = args.map_frame
    if args.laser_offset is not None:
        kw["laser_offset"] = tuple(args.laser_offset)
    return kw


def _refuse_bag_flags(args, path: Path) -> None:
    for flag, dest in _BAG_FLAGS.items():
        if getattr(args, dest, None):
            raise CLIError(f"{flag} applies to ROS bags; {path} is not one")


def _read_input(args) -> _Input:
    from ogm_ppl.datasets import load_dataset, read_bag, read_carmen

    if _is_bag(args.input):
        bag = read_bag(args.input, **_bag_kwargs(args, args.input))
        return _select_scans(args, _Input("bag", args.input, bag.scans, bag=bag))
    _refuse_bag_flags(args, args.input)
    magic = _check_input(args.input)
    image = _image_kind(magic)
    if image:
        raise CLIError(
            f"{args.input}: a {image} image (a floor plan?), not a log, bag or dataset file; ogm-ppl simulate "
            "--map PLAN.png scans a plan into a dataset that ogm-ppl map reads"
        )
    if magic[:2] == b"PK":
        for flag, value in (
            ("--lenient", args.lenient),
            ("--max-usable-range", args.max_usable_range),
            ("--no-return", args.no_return),
        ):
            if value:
                raise CLIError(f"{flag} applies to CARMEN logs and ROS bags; {args.input} is a dataset file")
        ds = load_dataset(args.input)
        scans = ds.scans
        kw = _reader_kwargs(args)
        if kw["pose_step"] != 1 or kw["pose_fraction"] is not None or args.beam_step != 1:
            scans = scans.subsample(kw["pose_step"], args.beam_step, kw["pose_fraction"])
        inp = _Input("dataset", args.input, scans, ds.grid, ds.truth, settings=ds.settings or {})
        return _select_scans(args, inp)
    log = read_carmen(args.input, **_reader_kwargs(args))
    return _select_scans(args, _Input("carmen", args.input, log.scans, log=log))


def _make_grid(args, inp: _Input) -> Grid:
    scans = inp.scans
    if getattr(args, "crop", False) and args.size is None:
        raise CLIError("--crop needs the grid's --size W H (and --origin X Y): the automatic extent covers all data")
    if args.size is not None:
        res = args.resolution or (inp.grid.resolution if inp.grid is not None else 0.05)
        cols, rows = args.size
        _check_cells(rows, cols, args.max_cells)
        grid = Grid((rows, cols), res, tuple(args.origin) if args.origin else (0.0, 0.0))
    elif (
        inp.grid is not None
        and inp.grid.ndim == 2
        and args.resolution is None
        and args.margin is None
        and args.origin is None
    ):
        grid = inp.grid
        _check_cells(grid.rows, grid.cols, args.max_cells)
    else:
        res = args.resolution or 0.05
        margin = 1.0 if args.margin is None else args.margin
        xmin, xmax, ymin, ymax = scans.extent()
        if args.origin is not None:
            ox, oy = args.origin
            if ox > xmin or oy > ymin:
                raise CLIError(
                    f"--origin {ox} {oy} lies above/right of the data (poses and hits from x = "
                    f"{xmin:.2f}, y = {ymin:.2f}); give a smaller origin or --size"
                )
        else:
            ox, oy = xmin - margin, ymin - margin
        cols = max(1, math.ceil((xmax + margin - ox) / res))
        rows = max(1, math.ceil((ymax + margin - oy) / res))
        _check_cells(rows, cols, args.max_cells)
        grid = Grid((rows, cols), res, (ox, oy))
    return grid


def _scans_on_grid(args, inp: _Input, grid: Grid) -> _Input:
    """``inp`` with every pose on ``grid``: as it is, or (``--crop``) keeping the scans whose pose lies on it;
    a pose off the grid without ``--crop`` is an error naming the scan."""
    scans = inp.scans
    inside = grid.contains(scans.poses[:, :2])
    if inside.all():
        return inp
    xa, xb, ya, yb = grid.extent
    where = f"the grid (x {xa:.3f} .. {xb:.3f}, y {ya:.3f} .. {yb:.3f})"
    if getattr(args, "crop", False):
        if not inside.any():
            raise CLIError(f"--crop: no pose of the {len(inside)} scans lies on {where}")
        steps = inp.selection or (f"{len(inside):,} read",)
        kept = int(inside.sum())
        return dataclasses.replace(inp, scans=scans.select(inside), selection=(*steps, f"--crop: {kept:,}"))
    s = int(np.flatnonzero(~inside)[0])
    x, y = scans.poses[s, :2]
    hint = "; --crop maps the part the grid covers" if args.size is not None else ""
    raise CLIError(
        f"pose of scan {s} at ({x:.3f}, {y:.3f}) lies outside {where}; {(~inside).sum()} of {len(inside)} poses "
        f"are outside{hint}"
    )


def _method_params(args) -> tuple[MapMethod, object]:
    """The method of ``--method`` and its parameters: the flags of :data:`METHOD_FLAGS` that were given,
    then the command line's defaults (:data:`CLI_SWEEPS`, burn-in ``sweeps // 10``, :data:`CLI_LAMBDA`)
    where the method has those parameters, then ``--param KEY=VALUE`` (command-line strings)."""
    try:
        method = get_method(args.method)
    except ParamError as e:
        raise CLIError(f"argument --method: {e.message}") from None
    names = method.param_names()
    values: dict = {}
    source: dict = {}
    for flag, (key, dest) in METHOD_FLAGS.items():
        v = getattr(args, dest)
        if v is None:
            continue
        if key not in names:
            having = [m.name for m in methods() if key in m.param_names() and m.alias_of is None]
            raise CLIError(
                f"{flag} sets the parameter {key!r} of {', '.join(having) or 'no method'}; "
                f"--method {method.name} has none"
            )
        values[key], source[key] = v, f"argument {flag}"
    for item in args.param:
        key, eq, v = item.partition("=")
        if not eq or not key.strip():
            raise CLIError(f"argument --param: expected KEY=VALUE, got {item!r}")
        key = key.strip()
        if key in values:
            raise CLIError(f"--param {key} repeats {source[key]}")
        values[key], source[key] = v, f"--param {key}"
    if "sweeps" in names:
        values.setdefault("sweeps", str(CLI_SWEEPS))
    if "burn_in" in names and "burn_in" not in values:
        try:
            values["burn_in"] = str(int(values["sweeps"]) // 10)
        except ValueError:
            pass  # a bad --param sweeps is reported below
    if "lam" in names and values.get("prior", method.default_params().prior) == "independent":
        values.setdefault("lam", str(CLI_LAMBDA))
    text = {k: str(v) for k, v in values.items()}
    try:
        params = method.parse(text, text=True)
    except ParamError as e:
        where = source.get(e.key, f"parameter {e.key}")
        raise CLIError(f"{where}: {e.message}") from None
    patch = getattr(params, "patch", None)
    if isinstance(patch, int) and patch > 1 and math.isqrt(patch) ** 2 == patch:
        side = math.isqrt(patch)
        print(
            f"ogm-ppl: note: --patch {patch} is a run of {patch} cells in one row; square {side} x {side} patches "
            f"(L = {patch} in the thesis) are --patch {side}x{side}",
            file=sys.stderr,
        )
    return method, params


def _compute_map(
    args, method: MapMethod, params, inp: _Input, grid: Grid, times: dict
) -> tuple[np.ndarray, np.ndarray, dict]:
    """``(probabilities K float64, observed K bool, details)`` of ``method``: the marginals averaged over
    its ``chains`` (chain ``c`` seeded ``--seed + c``); warnings become lines ``ogm-ppl: warning: ...``."""
    sigma = float(inp.settings.get("sigma_cells") or 0) or None
    problem = MapProblem(grid, inp.scans, sigma_cells=sigma)
    if getattr(args, "online", False):
        return _online_map(args, method, params, problem, times)
    chains = int(getattr(params, "chains", 1))
    root = _checkpoint_root(args, params, inp, grid)
    probs, ray, total = [], None, 0.0
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        from ogm_ppl.inference._kernels import quiet_numba_ir_check

        quiet_numba_ir_check()
        for c in range(chains):
            where = f"ogm-ppl map {args.input}"
            folder = None if root is None else root / f"chain-{c}"
            if folder is not None and (folder / "gibbs.npz").exists():
                print(f"ogm-ppl: chain {c} resumes from its checkpoint in {folder}", file=sys.stderr)
            ctx = RunContext(seed=args.seed + c, checkpoint_dir=folder, cache_dir=args.out, progress=True, where=where)
            try:
                result = method.run(params, problem, ctx)
            except KeyboardInterrupt as e:
                if root is not None and any(root.glob("chain-*/gibbs.npz")):
                    raise KeyboardInterrupt(f"checkpoints kept in {root}: the same command resumes from them") from e
                raise
            assert result.probabilities is not None  # no stop_after on the command line
            probs.append(result.probabilities)
            ray = result.seconds["ray_cast"] if ray is None else ray
            total += result.seconds["map"] or 0.0
    for w in {str(w.message): w for w in caught}.values():
        print(f"ogm-ppl: warning: {_one_line(w.message)}", file=sys.stderr)  # type: ignore[arg-type]
    times["ray_cast_s"], times["map_s"] = ray, total
    details = {**dataclasses.asdict(params), **result.details, "seed": args.seed, "chains": chains}
    return np.mean(probs, axis=0) if chains > 1 else probs[0], result.observed, details


#: where ``map`` keeps a sampling method's checkpoints, inside ``--out`` (removed once the map is written)
CHECKPOINTS = ".checkpoints"


def _prior_digest(params) -> str | None:
    """:func:`~ogm_ppl.inference.mcmc.fingerprint.prior_name_digest` of the prior ``params`` names (what its
    tables, weights and settings are now); ``None`` without a prior name, or for one that builds only on the
    map's own grid (the run says what is wrong with it)."""
    from ogm_ppl.inference.mcmc.fingerprint import prior_name_digest

    name = getattr(params, "prior", None)
    if not isinstance(name, str):
        return None
    try:
        return prior_name_digest(name)
    except ValueError:
        return None


def _checkpoint_root(args, params, inp: _Input, grid: Grid) -> Path | None:
    """``DIR/.checkpoints/METHOD-KEY`` for a sampling method (``None`` for the others): ``KEY`` digests the
    command's settings, the prior's content (:func:`_prior_digest`), the input file's size and modification
    time and the grid, so that only the same command on the same input under the same prior resumes a chain
    (each chain in ``chain-C``; its checkpoint's fingerprint checks the model too,
    :func:`~ogm_ppl.inference.mcmc.run_gibbs`)."""
    import hashlib

    from ogm_ppl.methods._sampling import SamplingParams

    if not isinstance(params, SamplingParams) or getattr(args, "online", False):
        return None
    st = Path(args.input).stat()
    ignore = ("out", "traceback", "input", "unobserved", "thresholds")  # how the map is written, not computed
    key = {
        "settings": _jsonable({k: v for k, v in sorted(vars(args).items()) if k not in ignore}),
        "params": _jsonable(dataclasses.asdict(params)),
        "prior": _prior_digest(params),
        "input": [str(Path(args.input).resolve()), st.st_size, st.st_mtime_ns],
        "grid": [grid.rows, grid.cols, grid.resolution, *grid.origin],
    }
    digest = hashlib.sha256(json.dumps(key, sort_keys=True).encode()).hexdigest()[:16]
    return args.out / CHECKPOINTS / f"{args.method}-{digest}"


def _online_map(
    args, method: MapMethod, params, problem: MapProblem, times: dict
) -> tuple[np.ndarray, np.ndarray, dict]:
    """``--online``: the scans replayed one at a time into :class:`~ogm_ppl.inference.online.OnlineMap`
    (:func:`~ogm_ppl.inference.online.replay`); the snapshots ride in ``details["_snapshots"]``."""
    from ogm_ppl.inference.online import replay

    if method.name != "gibbs" or params.patch != 1 or params.chains != 1 or params.update == "thesis":
        raise CLIError("--online runs one single-cell Gibbs chain: use --method gibbs (patch 1, one chain)")
    if params.threads is not None:
        raise CLIError("--online sweeps around each new scan serially: drop --threads")
    # the offline chain's start, kept as the scans arrive: reached cells restart from thresholded OGM
    init_new = {"ogm": "ogm", "free": "keep"}.get(params.init)
    if init_new is None or (params.init == "ogm" and params.init_delta != "haehnel"):
        raise CLIError(
            f"--online starts from thresholded traditional OGM (init=ogm, init_delta=haehnel) or all free "
            f"(init=free), got init={params.init!r}, init_delta={params.init_delta!r}"
        )
    sensor = problem.sensor(params.sensor, params.sigma_cells, params.p_rand)
    t0 = time.perf_counter()
    r = replay(
        problem.grid,
        problem.scans,
        sensor,
        problem.prior(params.prior, params.lam),
        burn_in=params.burn_in,
        sweeps=params.sweeps,
        snapshot_every=args.snapshots,
        progress=True,  # a bar on a terminal, plain lines in a log once past 10 s
        seed=args.seed,
        update=params.update,
        init_new=init_new,
    )
    times["ray_cast_s"], times["map_s"] = None, time.perf_counter() - t0
    om = r.online
    details = {
        **dataclasses.asdict(params),
        "sigma_cells": problem.sigma(params.sigma_cells),  # the noise the sensor model was built with
        "sensor_model": repr(sensor),
        "kernel": "OnlineMap",
        "seed": args.seed,
        "online": {
            "scans": om.num_scans,
            "sweeps_per_scan": om.sweeps_per_scan,
            "full_every": om.full_every,
            "margin": om.margin,
            "init_new": om.init_new,
            "sweeps_total": om.sweeps_done,
            "full_sweeps": om.full_sweeps,
            "mean_seconds_per_scan": float(r.seconds_per_scan.mean()),
        },
        "_snapshots": r.snapshots,
    }
    return r.probabilities, r.observed, details


def _atomic_savez(path: Path, **arrays) -> None:
    with atomic_write(path) as f:
        np.savez_compressed(f, **arrays)


def save_map_png(path: Path, probabilities: np.ndarray, observed: np.ndarray, grid: Grid) -> None:
    """One pixel per cell on the thesis colour scale (:func:`ogm_ppl.viz.thesis_cmap`), unknown cells
    grey, north (largest y) up. Uses a 256-entry lookup table, so large maps cost 3 bytes a cell."""
    from PIL import Image

    from ogm_ppl.viz import thesis_cmap

    lut = np.round(thesis_cmap()(np.linspace(0.0, 1.0, 256))[:, :3] * 255).astype(np.uint8)
    p = np.nan_to_num(np.asarray(probabilities, dtype=np.float64).reshape(grid.shape), nan=0.5)
    idx = np.clip(np.rint(p * 255), 0, 255).astype(np.uint8)
    rgb = lut[idx]
    rgb[~np.asarray(observed, bool).reshape(grid.shape)] = _PNG_UNKNOWN
    img = Image.fromarray(np.ascontiguousarray(rgb[::-1]), "RGB")
    with atomic_write(path) as f:
        img.save(f, "PNG", compress_level=3)


def load_map(path: str | os.PathLike) -> dict:
    """Read a ``map.npz`` written by ``ogm-ppl map``: probabilities / observed (grid-shaped), grid, settings."""
    with np.load(path, allow_pickle=False) as z:
        if str(z["format"]) != MAP_FORMAT:
            raise ValueError(f"{path}: not an {MAP_FORMAT} file")
        g = z["grid"]
        grid = Grid((int(g[0]), int(g[1])), float(g[2]), (float(g[3]), float(g[4])))
        return {
            "probabilities": z["probabilities"],
            "observed": z["observed"],
            "grid": grid,
            "method": str(z["method"]),
            "settings": json.loads(str(z["settings"])),
        }


def _counts(inp: _Input) -> dict:
    s = inp.scans
    src = inp.log if inp.log is not None else inp.bag
    # the reader counts the beams of the scans it read: of those mapped unless --scans / --crop kept some
    present = int(src.counts["beams"]) if src is not None and not inp.selection else int(s.num_readings)
    c: dict[str, int | dict[str, int] | list[str]] = {
        "scans": s.num_scans,
        "beams": present,
        "valid_beams": s.num_valid,
        "dropped_beams": present - s.num_valid,
        "max_range_readings": int(s.is_max.sum()),
    }
    if inp.selection:  # --scans / --crop: the reader's counts below are of every scan read
        c["selection"] = list(inp.selection)
    if inp.log is not None:
        for k in ("no_return", "beyond_usable", "below_min"):
            c[k] = int(inp.log.counts.get(k, 0))
        c["bad_lines"] = len(inp.log.bad_lines)
        c["skipped_message_types"] = dict(inp.log.skipped_types)
    if inp.bag is not None:
        for k in ("no_return", "beyond_usable", "below_min", "scans_read", "no_pose", "pose_samples"):
            c[k] = int(inp.bag.counts.get(k, 0))
        c["bad_messages"] = len(inp.bag.bad_messages)
    return c


def _scores(probs, observed, inp: _Input, grid: Grid) -> dict | None:
    if inp.truth is None or inp.grid != grid:
        return None
    from ogm_ppl.metrics import best_f1, near_mapped_mask, roc_auc

    truth = np.asarray(inp.truth).astype(bool).ravel()
    mask = near_mapped_mask(observed.reshape(grid.shape), 10.0).ravel()
    if truth[mask].all() or not truth[mask].any():
        return None
    f1, thr = best_f1(probs, truth, mask=mask)
    return {
        "best_f1": f1,
        "best_threshold": thr,
        "roc_auc": roc_auc(probs, truth, mask=mask),
        "mask": "cells within 10 cells of an observed cell (Fig. 6.16b)",
    }


def cmd_map(args) -> dict:
    """``ogm-ppl map``: read, grid, map, write; returns the report."""
    method, params = _method_params(args)
    created = not args.out.exists()
    _prepare_out_dir(args.out)
    try:
        return _map(args, method, params)
    except BaseException:
        if created and args.out.is_dir() and not any(args.out.iterdir()):
            args.out.rmdir()  # leave no empty directory behind after an error
        raise


def _map(args, method, params) -> dict:
    from ogm_ppl.rosmap import save_ros_map

    times: dict = {}
    with _steps(4, f"ogm-ppl map ({args.method})") as bar:
        bar.set_postfix_str("reading")
        t0 = time.perf_counter()
        inp = _read_input(args)
        times["read_s"] = time.perf_counter() - t0
        bar.update()
        bar.set_postfix_str("grid")
        grid = _make_grid(args, inp)
        inp = _scans_on_grid(args, inp, grid)
        bar.update()
        bar.set_postfix_str("mapping")
        if getattr(args, "snapshots", None) is not None and not getattr(args, "online", False):
            raise CLIError("--snapshots needs --online")
        probs, observed, details = _compute_map(args, method, params, inp, grid, times)
        snapshots = details.pop("_snapshots", None)
        bar.update()
        bar.set_postfix_str("writing")
        t0 = time.perf_counter()
        settings = _jsonable({k: v for k, v in vars(args).items() if k not in ("traceback",)})
        settings["method_details"] = _jsonable(details)
        stage = StagedFolder(args.out)  # the folder is all old or all new outputs, whatever interrupts this
        out = stage.path
        _atomic_savez(
            out / "map.npz",
            format=np.array(MAP_FORMAT),
            format_version=np.int64(MAP_FORMAT_VERSION),
            probabilities=probs.reshape(grid.shape),
            observed=observed.reshape(grid.shape),
            grid=np.array([grid.rows, grid.cols, grid.resolution, *grid.origin], dtype=float),
            method=np.array(args.method),
            settings=np.array(json.dumps(settings)),
        )
        if snapshots:
            _atomic_savez(
                out / "snapshots.npz",
                scans=np.array([n for n, _ in snapshots], dtype=np.int64),
                probabilities=np.stack([p.reshape(grid.shape) for _, p in snapshots]),
            )
        shown = observed if args.unobserved == "unknown" else np.ones_like(observed)
        save_map_png(out / "map.png", probs, shown, grid)
        (out / "ros").mkdir(exist_ok=True)
        ros = save_ros_map(out / "ros" / "map.yaml", probs, grid, unknown=~shown, thresholds=args.thresholds)
        assert ros.sidecar is not None  # save_ros_map writes one by default (sidecar=True)
        times["write_s"] = time.perf_counter() - t0
        bar.update()
    report = {
        "ogm_ppl_version": _version(),
        "input": {"path": str(inp.path), "kind": inp.kind, "size_bytes": _size(inp.path)},
        "counts": _counts(inp),
        "grid": {
            "rows": grid.rows,
            "cols": grid.cols,
            "cells": grid.num_cells,
            "resolution_m": grid.resolution,
            "origin_m": list(grid.origin),
            "extent_m": list(grid.extent),
            "observed_cells": int(observed.sum()),
        },
        "method": {"name": method.name, "description": method.doc, **_jsonable(details)},
        "times_s": {
            "read": times["read_s"],
            "ray_cast": times["ray_cast_s"],
            "map": times["map_s"],
            "write": times["write_s"],
        },
        "files": [
            "map.npz",
            "map.png",
            str(Path("ros") / ros.yaml.name),
            str(Path("ros") / ros.image.name),
            str(Path("ros") / ros.sidecar.name),
            "report.json",
            "report.md",
        ]
        + (["snapshots.npz"] if snapshots else []),
        "scores_vs_truth": _scores(probs, observed, inp, grid),
        "settings": settings,
    }
    if inp.log is not None and args.lenient:
        report["bad_lines"] = [{"line": n, "reason": r} for n, r in inp.log.bad_lines[:1000]]
    if inp.bag is not None:
        report["bag"] = {"storage": inp.bag.storage, "scan_topic": inp.bag.scan_topic, "poses": inp.bag.pose_source}
        if args.lenient:
            report["bad_messages"] = [
                {"topic": t, "message": i, "reason": r} for t, i, r in inp.bag.bad_messages[:1000]
            ]
    atomic_write_text(out / "report.json", json.dumps(_jsonable(report), indent=2))
    atomic_write_text(out / "report.md", _report_md(report))
    stage.commit()
    _drop_own_checkpoints(args, _checkpoint_root(args, params, inp, grid))
    return report


def _drop_own_checkpoints(args, own: Path | None) -> None:
    """The map is written: its chains' checkpoints are spent. Those of other commands run into the same folder
    (other settings or input, interrupted) stay, and a note says where they are."""
    root = args.out / CHECKPOINTS
    if own is not None:
        shutil.rmtree(own, ignore_errors=True)
    try:
        others = sorted(p.name for p in root.iterdir())
    except OSError:
        return
    if not others:
        root.rmdir()
        return
    print(
        f"ogm-ppl map: {root} keeps the checkpoints of {len(others)} other interrupted run(s) ({', '.join(others)}): "
        "rerunning their command resumes them; delete the folder to drop them",
        file=sys.stderr,
    )


def _size(path: Path) -> int:
    """Bytes of a file, or of every file under a folder (a ROS 2 bag)."""
    if path.is_dir():
        return sum(p.stat().st_size for p in path.rglob("*") if p.is_file())
    return path.stat().st_size


def _plural(n: int, noun: str) -> str:
    """``"1 scan"``, ``"2 scans"``."""
    return f"{n:,} {noun}{'' if n == 1 else 's'}"


def _fmt_s(x) -> str:
    return "fused with map" if x is None else f"{x:.3f} s"


def _report_md(r: dict) -> str:
    c, g, t, m = r["counts"], r["grid"], r["times_s"], r["method"]
    of = f" ({'; '.join(c['selection'])})" if "selection" in c else ""
    over = " (over all the scans read)" if "selection" in c else ""
    lines = [
        f"# ogm-ppl map: {Path(r['input']['path']).name}",
        "",
        f"- input: `{r['input']['path']}` ({r['input']['kind']}, {r['input']['size_bytes']:,} bytes)",
        f"- scans: {c['scans']:,}{of}; beams: {c['beams']:,}; valid: {c['valid_beams']:,}; dropped: "
        f"{c['dropped_beams']:,}; max-range readings: {c['max_range_readings']:,}",
    ]
    if "no_return" in c:
        bad = f"bad lines: {c['bad_lines']}" if "bad_lines" in c else f"bad messages: {c['bad_messages']}"
        lines.append(
            f"- dropped by rule: no return {c['no_return']:,}, beyond usable range "
            f"{c['beyond_usable']:,}, below min range {c['below_min']:,}{over}; {bad}"
        )
    if "no_pose" in c:
        b = r["bag"]
        lines.append(
            f"- bag ({b['storage']}): {c['scans_read']:,} scans on {b['scan_topic']}, {c['no_pose']:,} dropped "
            f"without a pose; poses from {b['poses']} ({c['pose_samples']:,} samples)"
        )
    lines += [
        f"- grid: {g['cols']} x {g['rows']} cells ({g['cells']:,}) at {g['resolution_m']} m, origin "
        f"({g['origin_m'][0]:.3f}, {g['origin_m'][1]:.3f}); observed cells: {g['observed_cells']:,}",
        f"- method: {m['name']} ({m['description']})"
        + "".join(f"; {k} = {v}" for k, v in m.items() if k not in ("name", "description")),
        f"- times: read {_fmt_s(t['read'])}, ray cast {_fmt_s(t['ray_cast'])}, map {_fmt_s(t['map'])}, "
        f"write {_fmt_s(t['write'])}",
    ]
    if r.get("scores_vs_truth"):
        sc = r["scores_vs_truth"]
        lines.append(
            f"- against the truth ({sc['mask']}): best F1 {sc['best_f1']:.3f} at "
            f"{sc['best_threshold']:.2f}, ROC AUC {sc['roc_auc']:.3f}"
        )
    lines += ["", "Files: " + ", ".join(f"`{f}`" for f in r["files"]) + "."]
    if r.get("bad_messages"):
        lines += ["", "## Skipped messages (--lenient)", ""]
        lines += [f"- {b['topic'] or 'storage'} message {b['message']}: {b['reason']}" for b in r["bad_messages"][:50]]
    if r.get("bad_lines"):
        lines += ["", "## Skipped lines (--lenient)", ""]
        lines += [f"- line {b['line']}: {b['reason']}" for b in r["bad_lines"][:50]]
        if len(r["bad_lines"]) > 50:
            lines.append(f"- ... {len(r['bad_lines']) - 50} more in report.json")
    return "\n".join(lines) + "\n"


def _truth_from_spec(spec: list[str], size: int, seed: int) -> tuple[np.ndarray, dict]:
    from ogm_ppl.datasets.mapgen import generate_map

    words = spec[1:] if spec[0] == "generated" else spec
    if len(words) == 1 and words[0].startswith("generated:"):
        words = [words[0][len("generated:") :]]
    if len(words) == 1 and words[0] in KINDS:
        border = min(20, size // 4)  # Fig. 5.9's 20-cell outer wall, thinner on small maps
        truth = generate_map(words[0], (size, size), seed=seed, border=border)
        return truth, {"map": "generated", "kind": words[0], "size": size, "border": border}
    if len(words) == 1 and spec[0] != "generated" and (words[0].lower().endswith(".png") or Path(words[0]).exists()):
        path = Path(words[0])
        _check_input(path)
        from PIL import Image, UnidentifiedImageError

        try:
            with Image.open(path) as im:
                grey = np.asarray(im.convert("L"))
        except (UnidentifiedImageError, OSError) as e:
            raise CLIError(f"{path}: not a readable image ({e})") from None
        occ = grey < 128
        occ[[0, -1], :] = occ[:, [0, -1]] = True  # a closed outer wall: beams end inside the map
        return occ[::-1].copy(), {"map": "png", "path": str(path)}  # image row 0 is the top (largest y)
    raise CLIError(
        f"argument --map: expected 'generated KIND' with KIND one of {', '.join(KINDS)}, "
        f"or a PNG file; got {' '.join(spec)!r}"
    )


def cmd_simulate(args) -> dict:
    """``ogm-ppl simulate``: stop-and-scan dataset on a generated map or PNG, saved with its truth."""
    from ogm_ppl.datasets import save_dataset
    from ogm_ppl.datasets.stop_and_scan import stop_and_scan

    _prepare_out_file(args.out)
    with _steps(3, "ogm-ppl simulate") as bar:
        bar.set_postfix_str("ground truth")
        truth, source = _truth_from_spec(args.map, args.size, args.seed)
        grid = Grid(truth.shape, args.resolution)
        bar.update()
        bar.set_postfix_str("route and scans")
        t0 = time.perf_counter()
        data = stop_and_scan(
            truth,
            grid,
            num_poses=args.poses,
            beams=args.beams,
            max_range_cells=args.max_range_cells,
            sigma_cells=args.sigma,
            seed=args.seed,
        )
        seconds = time.perf_counter() - t0
        bar.update()
        bar.set_postfix_str("writing")
        settings = dict(data.settings, **source, resolution=args.resolution, generator="stop_and_scan")
        save_dataset(
            args.out,
            data.scans,
            grid=grid,
            truth=data.truth,
            settings=_jsonable(settings),
            provenance={"tool": "ogm-ppl simulate", "ogm_ppl_version": _version()},
        )
        bar.update()
    return {
        "poses": data.scans.num_scans,
        "beams": data.scans.beams_per_scan,
        "grid": list(grid.shape),
        "seconds": seconds,
    }


def cmd_convert(args) -> dict:
    """``ogm-ppl convert``: CARMEN log or ROS bag -> dataset file."""
    from ogm_ppl.datasets import read_bag, read_carmen, save_dataset

    if _is_bag(args.log):
        kw = _bag_kwargs(args, args.log)
        _prepare_out_file(args.out)
        t0 = time.perf_counter()
        bag = read_bag(args.log, **kw)
        seconds = time.perf_counter() - t0
        grid = bag.grid(args.resolution) if args.resolution else None
        provenance = {
            "tool": "ogm-ppl convert",
            "source": str(args.log),
            "reader": "ogm_ppl.datasets.read_bag",
            "ogm_ppl_version": _version(),
            "storage": bag.storage,
            "bad_messages": len(bag.bad_messages),
            "counts": bag.counts,
        }
        save_dataset(args.out, bag.scans, grid=grid, settings=_jsonable(bag.settings), provenance=_jsonable(provenance))
        return {
            "scans": bag.scans.num_scans,
            "beams": bag.scans.beams_per_scan,
            "bad_lines": len(bag.bad_messages),
            "what": "bad messages",
            "seconds": seconds,
        }
    _refuse_bag_flags(args, args.log)
    _check_input(args.log)
    _prepare_out_file(args.out)
    t0 = time.perf_counter()
    log = read_carmen(args.log, **_reader_kwargs(args))
    seconds = time.perf_counter() - t0
    grid = log.grid(args.resolution) if args.resolution else None
    provenance = {
        "tool": "ogm-ppl convert",
        "source": str(args.log),
        "reader": "ogm_ppl.datasets.read_carmen",
        "ogm_ppl_version": _version(),
        "num_lines": log.num_lines,
        "bad_lines": len(log.bad_lines),
        "counts": log.counts,
    }
    save_dataset(args.out, log.scans, grid=grid, settings=_jsonable(log.settings), provenance=_jsonable(provenance))
    return {
        "scans": log.scans.num_scans,
        "beams": log.scans.beams_per_scan,
        "bad_lines": len(log.bad_lines),
        "what": "bad lines",
        "seconds": seconds,
    }


def _deg(x: float) -> float:
    return round(math.degrees(float(x)), 9)


def _scan_stats(scans: Scans) -> dict:
    """Beam geometry, range limits and extent of read scans (angles in degrees, lengths in metres)."""
    a = scans.angles
    inc = np.round(np.degrees(np.diff(a, axis=1)), 9) if scans.beams_per_scan > 1 else np.zeros((1, 1))
    hit = scans.valid & ~scans.is_max
    xmin, xmax, ymin, ymax = scans.extent()
    return {
        "scans": scans.num_scans,
        "beams_per_scan": scans.beams_per_scan,
        "angular_increment_deg": sorted({float(v) for v in np.unique(inc)})[:10],
        "field_of_view_deg": _deg(float((a[:, -1] - a[:, 0]).max())),
        "first_beam_deg": _deg(float(a[:, 0].min())),
        "last_beam_deg": _deg(float(a[:, -1].max())),
        "max_range_m": scans.max_range,
        "min_range_m": scans.min_range,
        "largest_hit_m": float(scans.ranges[hit].max()) if hit.any() else None,
        "smallest_hit_m": float(scans.ranges[hit].min()) if hit.any() else None,
        "valid_beams": scans.num_valid,
        "max_range_readings": int(scans.is_max.sum()),
        "extent_m": {"x": [xmin, xmax], "y": [ymin, ymax], "width": xmax - xmin, "height": ymax - ymin},
    }


def _rate(n: int, stamps: np.ndarray) -> float | None:
    span = float(stamps.max() - stamps.min()) if len(stamps) else 0.0
    return (n - 1) / span if span > 0 and n > 1 else None


def cmd_info(args) -> dict:
    """``ogm-ppl info``: what a CARMEN log, ROS bag or dataset file holds, read with the reader options."""
    from ogm_ppl.datasets import load_dataset, read_bag, read_carmen
    from ogm_ppl.datasets.rosbag import bag_info

    path = args.input
    if _is_bag(path):
        kw = _bag_kwargs(args, path, pose_required=False)
        info = bag_info(path, kw["scan_topic"], strict=not args.lenient)
        r: dict = {"input": str(path), "kind": "bag", "storage": info["storage"], "topics": info["topics"]}
        r["scan_topic"] = info.get("scan_topic")
        r["laser_frames"] = info.get("frames")
        r["message_range_min_m"] = info.get("range_min")
        r["message_range_max_m"] = info.get("range_max")
        r["no_return_rule"] = "NaN, +Inf or >= range_max of the message" + (
            f", or >= {args.no_return_threshold} m" if getattr(args, "no_return_threshold", None) else ""
        )
        r["no_return_beams_in_bag"] = info.get("no_return_beams")
        if "pose_topic" not in kw:  # the geometry from the scan messages alone
            if info.get("scans"):
                r["scans"] = info["scans"]
                r["beams_per_scan"] = info["beams_per_scan"]
                r["angular_increment_deg"] = [_deg(v) for v in info["angle_increment"]]
                r["field_of_view_deg"] = _deg(info["field_of_view"])
                r["first_beam_deg"], r["last_beam_deg"] = _deg(info["first_angle"]), _deg(info["last_angle"])
                r["duration_s"], r["scan_rate_hz"] = info["duration"], info["scan_rate_hz"]
            r["poses"] = "none found: give --pose-topic or --tf for the extent and the pose rate"
            return r
        bag = read_bag(path, **kw)
        r.update(_scan_stats(bag.scans))
        r["counts"] = bag.counts
        r["poses"] = bag.pose_source
        r["duration_s"] = float(np.ptp(bag.timestamps)) if len(bag.timestamps) else 0.0
        r["scan_rate_hz"] = _rate(bag.scans.num_scans, bag.timestamps)
        r["pose_rate_hz"] = _rate(len(bag.pose_timestamps), bag.pose_timestamps)
        r["bad_messages"] = len(bag.bad_messages)
        return r
    _refuse_bag_flags(args, path)
    magic = _check_input(path)
    if magic[:2] == b"PK":
        ds = load_dataset(path)
        r = {"input": str(path), "kind": "dataset", **_scan_stats(ds.scans)}
        r["grid"] = None if ds.grid is None else {"shape": list(ds.grid.shape), "resolution_m": ds.grid.resolution}
        r["truth"] = ds.truth is not None
        r["duration_s"] = r["scan_rate_hz"] = r["pose_rate_hz"] = None  # a dataset file keeps no stamps
        return r
    log = read_carmen(path, **_reader_kwargs(args))
    st = log.settings
    if st.get("no_return_threshold") is not None:
        rule = f">= {st['no_return_threshold']} m (given)"
    elif st.get("auto_no_return_threshold") is not None:
        rule = f">= {st['auto_no_return_threshold']} m (the FLASER sentinel band of the log's largest reading)"
    elif "ROBOTLASER1" in st.get("messages", []):
        rule = ">= the max_range of each ROBOTLASER1 line"
    else:
        rule = "none (no sentinel band found)"
    r = {"input": str(path), "kind": "carmen", "messages": st.get("messages"), **_scan_stats(log.scans)}
    r["no_return_rule"] = rule
    r["counts"] = log.counts
    ts = log.timestamps
    r["duration_s"] = float(np.ptp(ts)) if len(ts) else 0.0
    r["scan_rate_hz"] = _rate(log.scans.num_scans, ts)
    r["pose_rate_hz"] = r["scan_rate_hz"]  # every scan line carries its pose
    odom = log.skipped_types.get("ODOM", 0)
    r["odometry_rate_hz"] = odom / r["duration_s"] if odom and r["duration_s"] else None
    r["bad_lines"] = len(log.bad_lines)
    r["skipped_message_types"] = log.skipped_types
    return r


def _fmt_v(v) -> str:
    if isinstance(v, float):
        return f"{v:.6g}"
    if isinstance(v, list):
        return ", ".join(_fmt_v(x) for x in v) if v else "-"
    if isinstance(v, dict):
        return "; ".join(f"{k} {_fmt_v(x)}" for k, x in v.items())
    return "-" if v is None else str(v)


def _info_text(r: dict) -> str:
    """``ogm-ppl info`` as aligned ``key: value`` lines (topics one a line)."""
    lines = []
    for k, v in r.items():
        if k == "topics":
            lines.append("topics:")
            lines += [f"  {t['topic']}  {t['type']}  {t['messages']} messages" for t in v]
        elif k == "laser" and isinstance(v, dict):
            lines.append("laser (from the scan messages):")
            lines += [f"  {kk}: {_fmt_v(vv)}" for kk, vv in v.items() if kk not in ("laser_topics",)]
        else:
            lines.append(f"{k}: {_fmt_v(v)}")
    return "\n".join(lines)


def _one_line(e: BaseException) -> str:
    if isinstance(e, OSError) and not str(e).strip(": "):
        text = type(e).__name__
    elif isinstance(e, OSError) and e.strerror:
        text = f"{e.filename}: {e.strerror}" if e.filename else e.strerror
    else:
        text = str(e) or type(e).__name__
    return " ".join(text.split())


def cmd_methods(args) -> str:
    """``ogm-ppl methods [NAME]``: each method's name, one line and parameters (default, kind, meaning)."""
    cli_defaults = (
        f"ogm-ppl map's own defaults, where a method has the parameter: sweeps = {CLI_SWEEPS}, burn_in = sweeps // "
        f"10, lam = {CLI_LAMBDA} (prior independent); specs and the Python API use the defaults listed"
    )
    if args.name is not None:
        try:
            m = get_method(args.name)
        except ParamError as e:
            raise CLIError(f"argument NAME: {e.message}") from None
        shared = {"sweeps", "burn_in", "lam"} & set(m.param_names())
        return "\n".join([*m.describe(), *(["", cli_defaults] if shared else [])])
    from ogm_ppl.priors import prior_kinds
    from ogm_ppl.sensors import sensor_kinds

    lines = []
    for m in methods():
        lines += [f"{m.name}: {m.doc}"] if m.alias_of else m.describe()
    lines += [
        "",
        f"prior kinds (parameter prior, KIND[:CORPUS][@BETA|@cal]): {', '.join(prior_kinds())}",
        f"sensor kinds (parameter sensor): {', '.join(sensor_kinds())}",
        cli_defaults,
    ]
    return "\n".join(lines)


def cmd_experiment(args) -> int:
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
        if args.command == "run":
            _prepare_out_dir(args.out)
            from ogm_ppl.experiment.headline import run_headline

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
        elif args.command == "map":
            r = cmd_map(args)
            t = r["times_s"]
            print(
                f"ogm-ppl map: {r['grid']['cols']} x {r['grid']['rows']} cells, "
                f"{_plural(r['counts']['scans'], 'scan')}, method {args.method}; read {_fmt_s(t['read'])}, "
                f"map {_fmt_s(t['map'])} -> {args.out}"
            )
        elif args.command == "simulate":
            r = cmd_simulate(args)
            print(
                f"ogm-ppl simulate: {r['poses']} poses x {r['beams']} beams on {r['grid'][1]} x {r['grid'][0]} "
                f"cells -> {args.out}"
            )
        elif args.command == "experiment":
            return cmd_experiment(args)
        elif args.command == "calibrate":
            from ogm_ppl.calibration import _command as calibrate_command

            return calibrate_command.run(args)
        elif args.command == "methods":
            print(cmd_methods(args))
        elif args.command == "convert":
            r = cmd_convert(args)
            print(
                f"ogm-ppl convert: {r['scans']} scans x {r['beams']} beams ({r['bad_lines']} {r['what']} "
                f"skipped) -> {args.out}"
            )
        elif args.command == "info":
            r = cmd_info(args)
            print(json.dumps(_jsonable(r), indent=2) if args.json else _info_text(r))
        return 0
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


if __name__ == "__main__":  # python -m ogm_ppl.cli, as python -m ogm_ppl
    raise SystemExit(main())
