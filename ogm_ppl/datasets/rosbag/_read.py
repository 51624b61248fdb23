"""Reading scans and poses from a bag into :class:`~ogm_ppl.scans.Scans` (:func:`read_bag`) with the beam
rules of :mod:`ogm_ppl.datasets.rosbag`."""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ogm_ppl.datasets.carmen import ScanLog, _kept_scans, beam_rules
from ogm_ppl.datasets.rosbag._errors import BagFormatError
from ogm_ppl.datasets.rosbag._messages import (
    LASER_SCAN,
    POSE_TYPES,
    TF_MESSAGE,
    _connections,
    _pose_record,
    _read_messages,
    _scan_record,
    _tf_records,
)
from ogm_ppl.datasets.rosbag._numbers import _widen_array
from ogm_ppl.datasets.rosbag._open import _open_reader
from ogm_ppl.datasets.rosbag._poses import _poses_from_topic
from ogm_ppl.datasets.rosbag._tf import _poses_from_tf
from ogm_ppl.scans import Scans


@dataclass
class BagLog(ScanLog):
    """Scans read from a bag (every rule applied is in the :mod:`ogm_ppl.datasets.rosbag` docstring).

    Attributes:
        scans: the scans that have a pose, in bag order (receive time), with ``scans.valid`` marking dropped beams.
        path: the bag read; ``storage``: ``"ros1"``, ``"sqlite3"`` or ``"mcap"``.
        scan_topic, pose_source: the LaserScan topic, and the pose topic or ``"tf"``.
        bad_messages: ``(topic, index, reason)`` of every message skipped as malformed (lenient mode).
        max_range: the ``max_range`` given to :class:`Scans` (metres).
        settings: every option and derived value used (JSON-serialisable).
        message_indices: ``S`` 0-based index of each kept scan on the scan topic.
        timestamps: ``S`` scan stamps in seconds; ``pose_timestamps``: the stamps of the pose samples
            (of the first dynamic link for ``tf``).
        counts: ``scans_read``, ``no_pose`` (scans dropped for want of a pose), ``pose_samples``, and beams
            per outcome as :class:`~ogm_ppl.datasets.carmen.CarmenLog`: ``beams``, ``valid``, ``no_return``,
            ``beyond_usable``, ``below_min``, ``max_range_readings`` (of the kept scans).
    """

    scans: Scans
    path: str
    storage: str
    scan_topic: str
    pose_source: str
    bad_messages: list[tuple[str, int, str]]
    max_range: float
    settings: dict
    message_indices: np.ndarray = field(repr=False)
    timestamps: np.ndarray = field(repr=False)
    pose_timestamps: np.ndarray = field(repr=False)
    counts: dict[str, int] = field(default_factory=dict)


def read_bag(
    path: str | os.PathLike,
    scan_topic: str,
    pose_topic: str | None = None,
    *,
    tf: bool = False,
    map_frame: str = "map",
    laser_offset: tuple[float, float, float] = (0.0, 0.0, 0.0),
    pose_tolerance: float = 0.1,
    strict: bool = True,
    max_usable_range: float | None = None,
    usable_range_rule: str = "drop",
    no_return: str = "drop",
    no_return_threshold: float | None = None,
    min_range: float = 0.0,
    max_range: float | None = None,
    pose_step: int = 1,
    pose_fraction: float | None = None,
    beam_step: int = 1,
    widen: str = "decimal",
) -> BagLog:
    """Read the ``sensor_msgs/LaserScan`` messages of ``scan_topic`` and the laser poses of a bag.

    Args:
        path: a ROS 1 ``.bag`` file, a ROS 2 bag folder (sqlite3 or MCAP), or a bare ``.db3`` / ``.mcap``.
        scan_topic: the LaserScan topic.
        pose_topic: a ``nav_msgs/Odometry``, ``geometry_msgs/PoseStamped`` or
            ``PoseWithCovarianceStamped`` topic giving the robot pose (give it or ``tf``, not both).
        tf: take the poses from ``/tf`` + ``/tf_static``: ``map_frame -> ... -> the scans' frame_id``.
        map_frame: the world frame of the poses in ``tf`` mode.
        laser_offset: ``(x, y, yaw)`` of the laser in the robot frame (metres, radians), pose-topic mode.
        pose_tolerance: seconds; a scan farther than this from the pose samples around it is dropped.
        strict: raise :class:`BagFormatError` on the first malformed message (default); with False,
            skip malformed messages and list them in ``bad_messages``.
        max_usable_range: as :func:`~ogm_ppl.datasets.carmen.read_carmen`; likewise ``usable_range_rule``,
            ``no_return``, ``no_return_threshold``, ``min_range``, ``max_range``, ``pose_step``,
            ``pose_fraction`` and ``beam_step`` (the no-return rule for bags: :mod:`ogm_ppl.datasets.rosbag`).
        widen: ``"decimal"`` or ``"binary"``: how float32 fields become float64 (:mod:`ogm_ppl.datasets.rosbag`).

    Returns:
        a :class:`BagLog`; ``log.scans`` is the same :class:`Scans` that ``read_carmen`` gives for the
        same readings and poses.
    """
    path = Path(path)
    if (pose_topic is None) == (not tf):
        raise ValueError("read_bag: give pose_topic or tf=True (one pose source)")
    for name, v, allowed in (
        ("usable_range_rule", usable_range_rule, ("drop", "max")),
        ("no_return", no_return, ("drop", "max")),
        ("widen", widen, ("decimal", "binary")),
    ):
        if v not in allowed:
            raise ValueError(f"read_bag: {name} must be one of {allowed}, got {v!r}")
    for opt, x in (
        ("max_usable_range", max_usable_range),
        ("no_return_threshold", no_return_threshold),
        ("max_range", max_range),
    ):
        if x is not None and not (isinstance(x, (int, float)) and math.isfinite(x) and x > 0):
            raise ValueError(f"read_bag: {opt} must be a finite number > 0 or None, got {x!r}")
    if not (isinstance(min_range, (int, float)) and math.isfinite(min_range) and min_range >= 0):
        raise ValueError(f"read_bag: min_range must be a finite number >= 0, got {min_range!r}")
    if not (isinstance(pose_tolerance, (int, float)) and math.isfinite(pose_tolerance) and pose_tolerance >= 0):
        raise ValueError(f"read_bag: pose_tolerance must be a finite number of seconds >= 0, got {pose_tolerance!r}")
    off = tuple(laser_offset)
    if len(off) != 3 or not all(isinstance(v, (int, float)) and math.isfinite(v) for v in off):
        raise ValueError(f"read_bag: laser_offset must be three finite numbers (x, y, yaw), got {laser_offset!r}")
    if pose_fraction is not None and pose_step != 1:
        raise ValueError("read_bag: give pose_step or pose_fraction, not both")
    if pose_step < 1 or beam_step < 1 or not (pose_fraction is None or 0 < pose_fraction <= 1):
        raise ValueError(
            f"read_bag: need pose_step, beam_step >= 1 and pose_fraction in (0, 1], got "
            f"{pose_step}, {beam_step}, {pose_fraction}"
        )
    if not isinstance(scan_topic, str) or not scan_topic:
        raise ValueError(f"read_bag: scan_topic must be a topic name, got {scan_topic!r}")

    bad: list[tuple[str, int, str]] = []
    scans: list[tuple] = []
    poses: list[tuple] = []
    links: list[tuple] = []

    def handle(topic: str, index: int, msgtype: str, msg) -> None:
        if topic == scan_topic:
            scans.append((index, *_scan_record(msg, widen)))
        elif tf:
            links.extend(_tf_records(msg, static=topic == "/tf_static"))
        else:
            poses.append(_pose_record(msg, msgtype))

    with _open_reader(path, lenient=not strict) as (reader, kind):
        if getattr(reader, "note", None):
            bad.append(("", -1, reader.note))  # type: ignore[attr-defined]
        conns = _connections(path, reader, scan_topic, (LASER_SCAN,), "scan")
        if tf:
            tf_conns = [c for c in reader.connections if c.topic in ("/tf", "/tf_static")]  # type: ignore[attr-defined]
            if not tf_conns:
                raise BagFormatError(path, "tf=True but the bag has no /tf or /tf_static topic")
            for c in tf_conns:
                if c.msgtype != TF_MESSAGE:
                    raise BagFormatError(path, f"holds {c.msgtype}, expected {TF_MESSAGE}", topic=c.topic)
            conns += tf_conns
        else:
            assert pose_topic is not None
            conns += _connections(path, reader, pose_topic, POSE_TYPES, "pose")
        _read_messages(path, reader, conns, strict, bad, handle)
    if not scans:
        raise BagFormatError(path, "no readable LaserScan messages", topic=scan_topic)

    idx = np.array([s[0] for s in scans], dtype=np.int64)
    stamps = np.array([s[1] for s in scans], dtype=np.int64)
    tol_ns = round(pose_tolerance * 1e9)
    if tf:
        frames = [s[2] for s in scans]
        laser, have, flipped, pose_stamps = _poses_from_tf(path, links, frames, stamps, tol_ns, map_frame.lstrip("/"))
    else:
        flipped = np.zeros(len(stamps), dtype=bool)
        laser, have = _poses_from_topic(poses, stamps, tol_ns, off)
        pose_stamps = np.sort(np.array([p[0] for p in poses], dtype=np.int64))
    keep_pose = np.flatnonzero(have)
    if not len(keep_pose):
        raise BagFormatError(
            path,
            f"none of the {len(scans)} scans has a pose within {pose_tolerance} s "
            f"({'tf' if tf else pose_topic}: {len(pose_stamps)} samples)",
        )
    kept = [scans[i] for i in keep_pose]
    S, B = len(kept), max(len(s[7]) for s in kept)
    present = np.zeros((S, B), dtype=bool)
    r32 = np.zeros((S, B), dtype=np.float32)
    angles = np.zeros((S, B))
    for k, s in enumerate(kept):
        n = len(s[7])
        present[k, :n] = True
        r32[k, :n] = s[7]
        angles[k, :n] = s[3] + s[4] * np.arange(n)
        if flipped[keep_pose[k]]:
            angles[k, :n] = -angles[k, :n]
    rmin_msg = np.array([s[5] for s in kept])
    thr = np.array([s[6] for s in kept])
    ranges = _widen_array(r32, widen)
    settings = dict(
        scan_topic=scan_topic,
        pose_topic=pose_topic,
        tf=tf,
        map_frame=map_frame if tf else None,
        laser_offset=list(off),
        pose_tolerance=pose_tolerance,
        strict=strict,
        max_usable_range=max_usable_range,
        usable_range_rule=usable_range_rule,
        no_return=no_return,
        no_return_threshold=no_return_threshold,
        min_range=min_range,
        max_range=max_range,
        pose_step=pose_step,
        pose_fraction=pose_fraction,
        beam_step=beam_step,
        widen=widen,
        storage=kind,
        range_max=sorted({float(v) for v in thr})[:20],
        range_min=sorted({float(v) for v in rmin_msg})[:20],
        beam_counts=sorted({len(s[7]) for s in kept}),
        frames=sorted({s[2] for s in kept}),
    )
    scans_out, counts = _apply_rules(laser[keep_pose], angles, ranges, present, thr, rmin_msg, settings)
    keep = _kept_scans(S, pose_step, pose_fraction)
    counts = {"scans_read": len(scans), "no_pose": int(len(scans) - S), "pose_samples": len(pose_stamps), **counts}
    return BagLog(
        scans_out,
        str(path),
        kind,
        scan_topic,
        "tf" if tf else str(pose_topic),
        bad,
        float(scans_out.max_range),
        settings,
        idx[keep_pose][keep],
        stamps[keep_pose][keep] / 1e9,
        pose_stamps / 1e9,
        counts,
    )


def _apply_rules(poses, angles, ranges, present, thr, rmin_msg, st) -> tuple[Scans, dict[str, int]]:
    """The no-return, usable-range, min-range and subsampling rules, in the order ``read_carmen``
    applies them; returns the scans and the beam counts of the kept scans."""
    if st["no_return_threshold"] is not None:
        thr = np.minimum(thr, float(st["no_return_threshold"]))
    no_ret = present & (np.isnan(ranges) | (ranges == np.inf) | (ranges >= thr[:, None]))
    below_msg = present & ~no_ret & ((ranges == -np.inf) | (ranges < rmin_msg[:, None]))
    ranges = np.where(np.isfinite(ranges), ranges, 0.0)
    valid = present & ~below_msg
    u = st["max_usable_range"]
    beyond = valid & ~no_ret & (ranges >= u) if u is not None else np.zeros_like(valid)
    mr = st["max_range"]
    if mr is None:
        mr = float(u) if u is not None else float(thr.max())
    scans, counts, _ = beam_rules(poses, angles, ranges, present, valid, no_ret, beyond, below_msg, mr, st)
    return scans, counts
