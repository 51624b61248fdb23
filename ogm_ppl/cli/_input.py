"""The input of ``ogm-ppl map``, ``convert`` and ``info``: a CARMEN log, a ROS bag or a dataset file, told
apart by magic bytes, read with the reader options, its scans selected and laid on a grid."""

from __future__ import annotations

import argparse
import dataclasses
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ogm_ppl.grid import Grid

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


_BAG_FLAGS = {
    "--scan-topic": "scan_topic",
    "--pose-topic": "pose_topic",
    "--tf": "tf",
    "--laser-offset": "laser_offset",
}


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
