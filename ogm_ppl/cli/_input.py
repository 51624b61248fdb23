"""The input of ``ogm-ppl map``, ``convert`` and ``info`` on the command line: the reader flags and what the
command line adds to :mod:`ogm_ppl.inputs` (which tells the input apart, checks the options and reads it): the
flags mapped onto the input kind's options, a bag's topics found in the bag, ``--scans``, the grid and
``--crop``."""

from __future__ import annotations

import argparse
import dataclasses
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ogm_ppl.grid import Grid
from ogm_ppl.inputs import InputData, InputKind, detect_input_kind, get_input_kind, input_kinds, read_input
from ogm_ppl.options import ParamError

if TYPE_CHECKING:
    from ogm_ppl.datasets.carmen import CarmenLog
    from ogm_ppl.datasets.rosbag import BagLog
    from ogm_ppl.scans import Scans
from ogm_ppl.cli._common import (
    CLIError,
    _finite,
    _fraction,
    _nonneg_float,
    _pos_float,
    _pos_int,
)


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


#: the reader flags: flag -> (argparse dest, the input kinds' option it sets); a flag left at its default sets
#: nothing, and a flag given for an input whose kind has no such option is refused naming the kinds that have it
_FLAGS: dict[str, tuple[str, str]] = {
    "--lenient": ("lenient", "strict"),
    "--max-usable-range": ("max_usable_range", "max_usable_range"),
    "--no-return": ("no_return", "no_return"),
    "--pose-step": ("pose_step", "pose_step"),
    "--pose-fraction": ("pose_fraction", "pose_fraction"),
    "--beam-step": ("beam_step", "beam_step"),
    "--scan-topic": ("scan_topic", "scan_topic"),
    "--pose-topic": ("pose_topic", "pose_topic"),
    "--tf": ("tf", "tf"),
    "--map-frame": ("map_frame", "map_frame"),
    "--laser-offset": ("laser_offset", "laser_offset"),
    "--pose-tolerance": ("pose_tolerance", "pose_tolerance"),
}
_FLAG_OF = {option: flag for flag, (_, option) in _FLAGS.items()}
_DEFAULTS: dict[str, Any] = {"pose_step": 1, "beam_step": 1, "map_frame": "map", "pose_tolerance": 0.1}


def _kinds_having(option: str) -> str:
    """``"CARMEN logs and ROS bags"``: the kinds that read a file and take ``option``."""
    kinds = [get_input_kind(n) for n in input_kinds()]
    nouns = [k.noun + "s" for k in kinds if k.reads_file and option in k.option_names()]
    return " and ".join([", ".join(nouns[:-1]), nouns[-1]] if len(nouns) > 2 else nouns)


def _flag_values(args, kind: InputKind, path: Path) -> dict:
    """The options the reader flags given set (``--lenient``: ``strict = false``); a flag the input's kind has
    no option for is refused. With ``--scans``, the thinning waits for the stretch (:func:`_select_scans`)."""
    values: dict = {}
    for flag, (dest, option) in _FLAGS.items():
        v = getattr(args, dest, None)
        if v is None or v is False or v == _DEFAULTS.get(dest):
            continue
        if option not in kind.option_names():
            raise CLIError(f"{flag} applies to {_kinds_having(option)}; {path} is a {kind.noun}")
        values[option] = False if flag == "--lenient" else list(v) if flag == "--laser-offset" else v
    if getattr(args, "scans", None) is not None:  # thinned after the stretch is cut
        values.pop("pose_step", None)
        values.pop("pose_fraction", None)
    return values


def _bag_sources(path: Path, values: dict, pose_required: bool) -> dict:
    """The bag options with the scan topic (by default the bag's only LaserScan topic) and, where none is given
    and ``pose_required`` is false, the pose source the bag has (its only pose topic, else /tf); a clear error
    naming the flag otherwise. Without a pose source the values hold none (``ogm-ppl info`` reads the scan
    messages alone)."""
    from ogm_ppl.datasets.rosbag import bag_info

    info = None
    if "scan_topic" not in values or ("pose_topic" not in values and not values.get("tf")):
        info = bag_info(path, laser=False, strict=values.get("strict", True))
    if "scan_topic" not in values:
        assert info is not None
        lasers = info["laser_topics"]
        if len(lasers) != 1:
            raise CLIError(
                f"{path}: give --scan-topic; the bag has {len(lasers)} LaserScan topics"
                + (f" ({', '.join(lasers)})" if lasers else "")
            )
        values["scan_topic"] = lasers[0]
    if "pose_topic" not in values and not values.get("tf"):
        assert info is not None
        if pose_required:
            cand = ", ".join(info["pose_topics"]) or "none"
            raise CLIError(
                f"{path}: give --pose-topic P (pose topics in the bag: {cand}) or --tf"
                + (" (the bag has /tf)" if info["tf"] else " (the bag has no /tf)")
            )
        if len(info["pose_topics"]) == 1:
            values["pose_topic"] = info["pose_topics"][0]
        elif info["tf"]:
            values["tf"] = True
    return values


def _input_values(args, path: Path, pose_required: bool = True) -> tuple[InputKind, dict]:
    """The kind of the input ``path`` (:func:`~ogm_ppl.inputs.detect_input_kind`) and the option values its
    flags give; a bag's topics and pose source completed from the bag (:func:`_bag_sources`)."""
    kind = get_input_kind(detect_input_kind(path))
    values = _flag_values(args, kind, path)
    if kind.name == "bag":  # the command line's own convenience: a spec names its topics
        values = _bag_sources(path, values, pose_required)
    return kind, values


def _parse_options(kind: InputKind, values: dict, path: Path):
    """``kind``'s options from ``values``; an error names the flag (``--laser-offset applies to --pose-topic``)."""
    try:
        return kind.parse(values)
    except ParamError as e:
        msg = e.message_naming(lambda k: _FLAG_OF.get(k, k))
        flag = _FLAG_OF.get(e.key)
        raise CLIError(f"{flag} {msg}" if flag else f"{path}: option {e.key} of a {kind.noun}: {msg}") from None


def _read(args, path: Path) -> tuple[InputKind, InputData]:
    """The input ``path`` read as its kind, with the options of the reader flags (``ogm-ppl convert``)."""
    kind, values = _input_values(args, path)
    return kind, read_input(kind.name, path, _parse_options(kind, values, path))


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
    kind: str  # the input kind's report label: "carmen", "bag", "dataset", ...
    path: Path
    scans: Scans
    grid: Grid | None = None  # the input's own grid (a dataset file's)
    truth: np.ndarray | None = None
    log: CarmenLog | None = None
    settings: dict = field(default_factory=dict)
    bag: BagLog | None = None
    selection: tuple[str, ...] = ()  # what --scans / --crop (and thinning after --scans) kept, step by step
    resume_key: dict = field(default_factory=dict)  # ogm_ppl.inputs.resume_key of the read


def _read_input(args) -> _Input:
    """``ogm-ppl map``'s input: told apart, read with the reader flags (:func:`_read`), then ``--scans``."""
    from ogm_ppl.datasets.carmen import CarmenLog
    from ogm_ppl.datasets.rosbag import BagLog

    kind, data = _read(args, args.input)
    rec = data.record
    inp = _Input(
        kind.report_label,
        args.input,
        data.scans,
        data.grid,
        data.truth,
        log=rec if isinstance(rec, CarmenLog) else None,
        settings=dict(data.settings) if not isinstance(rec, (CarmenLog, BagLog)) else {},
        bag=rec if isinstance(rec, BagLog) else None,
        resume_key=data.resume_key,
    )
    return _select_scans(args, inp)


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
