"""Message types and decoding: each LaserScan, pose or transform message checked field by field into a
record, and the message stream of a reader with the strict and lenient error rules."""

from __future__ import annotations

import math
from collections import defaultdict
from pathlib import Path

import numpy as np

from ogm_ppl.datasets.rosbag._errors import BagFormatError, _MsgError
from ogm_ppl.datasets.rosbag._numbers import _angle64, _widen
from ogm_ppl.datasets.rosbag._tf import _yaw

LASER_SCAN = "sensor_msgs/msg/LaserScan"
ODOMETRY = "nav_msgs/msg/Odometry"
POSE_STAMPED = "geometry_msgs/msg/PoseStamped"
POSE_COV_STAMPED = "geometry_msgs/msg/PoseWithCovarianceStamped"
TF_MESSAGE = "tf2_msgs/msg/TFMessage"
POSE_TYPES = (ODOMETRY, POSE_STAMPED, POSE_COV_STAMPED)
_MAX_BEAMS = 100_000


def _stamp(header) -> int:
    sec, nsec = int(header.stamp.sec), int(header.stamp.nanosec)
    if not 0 <= nsec < 1_000_000_000:
        raise _MsgError("header.stamp.nanosec", f"{nsec} is not in [0, 1e9)")
    return sec * 1_000_000_000 + nsec


def _finite(v, name: str) -> float:
    try:
        x = float(v)
    except (TypeError, ValueError):
        raise _MsgError(name, f"expected a number, got {v!r}") from None
    if not math.isfinite(x):
        raise _MsgError(name, f"{x!r} is not finite")
    return x


def _quat(o, name: str) -> np.ndarray:
    q = np.array([_finite(getattr(o, k), f"{name}.{k}") for k in ("x", "y", "z", "w")])
    norm = float(np.linalg.norm(q))
    if not 0.5 < norm < 1.5:
        raise _MsgError(name, f"not a rotation (quaternion norm {norm:.3g})")
    return q / norm


def _scan_record(msg, widen: str) -> tuple:
    """``(stamp ns, frame, angle_min, angle_increment, range_min, range_max, ranges float32)``."""
    stamp = _stamp(msg.header)
    r = np.asarray(msg.ranges)
    n = r.shape[0] if r.ndim == 1 else 0
    if r.ndim != 1 or n == 0:
        raise _MsgError("ranges", "a scan needs at least one beam")
    if n > _MAX_BEAMS:
        raise _MsgError("ranges", f"{n} beams, more than {_MAX_BEAMS}")
    amin = _finite(msg.angle_min, "angle_min")
    inc = _finite(msg.angle_increment, "angle_increment")
    amax = _finite(msg.angle_max, "angle_max")
    if inc == 0 and n > 1:
        raise _MsgError("angle_increment", f"is 0 for {n} beams")
    if abs(amin + (n - 1) * inc - amax) > 1.01 * abs(inc) + 1e-5:  # some drivers are one increment off
        raise _MsgError(
            "angle_max",
            f"{amax!r} does not match angle_min + (n - 1) * angle_increment = {amin + (n - 1) * inc!r} ({n} beams)",
        )
    rmin = _finite(msg.range_min, "range_min")
    rmax = _finite(msg.range_max, "range_max")
    if rmax <= 0:
        raise _MsgError("range_max", f"must be > 0, got {rmax!r}")
    if not 0 <= rmin < rmax:
        raise _MsgError("range_min", f"must lie in [0, range_max = {rmax!r}), got {rmin!r}")
    r32 = r.astype(np.float32, copy=False)
    neg = np.isfinite(r32) & (r32 < 0)
    if neg.any():
        i = int(np.argmax(neg))
        raise _MsgError(f"ranges[{i}]", f"{float(r32[i])!r} is negative")
    return (
        stamp,
        str(msg.header.frame_id).lstrip("/"),
        _angle64(amin, widen),
        _angle64(inc, widen),
        _widen(rmin, widen),
        _widen(rmax, widen),
        r32,
    )


def _pose_record(msg, msgtype: str) -> tuple[int, float, float, float]:
    """``(stamp ns, x, y, yaw)`` of a pose message."""
    stamp = _stamp(msg.header)
    pose, name = (msg.pose.pose, "pose.pose") if msgtype in (ODOMETRY, POSE_COV_STAMPED) else (msg.pose, "pose")
    x = _finite(pose.position.x, f"{name}.position.x")
    y = _finite(pose.position.y, f"{name}.position.y")
    q = _quat(pose.orientation, f"{name}.orientation")
    return stamp, x, y, float(_yaw(*q))


def _tf_records(msg, static: bool) -> list[tuple]:
    """``(parent, child, stamp ns, translation 3, rotation 4, static)`` of each transform."""
    out = []
    for j, tr in enumerate(msg.transforms):
        name = f"transforms[{j}]"
        parent = str(tr.header.frame_id).lstrip("/")
        child = str(tr.child_frame_id).lstrip("/")
        if not parent or not child or parent == child:
            raise _MsgError(f"{name}.child_frame_id", f"bad link {parent!r} -> {child!r}")
        t = tr.transform.translation
        tv = np.array([_finite(getattr(t, k), f"{name}.transform.translation.{k}") for k in "xyz"])
        q = _quat(tr.transform.rotation, f"{name}.transform.rotation")
        try:
            stamp = _stamp(tr.header)
        except _MsgError as e:
            raise _MsgError(f"{name}.{e.field}", e.message) from None
        out.append((parent, child, stamp, tv, q, static))
    return out


def _connections(path: Path, reader, topic: str, types: tuple[str, ...], role: str) -> list:
    conns = [c for c in reader.connections if c.topic == topic]
    if not conns:
        have = sorted({f"{c.topic} ({c.msgtype})" for c in reader.connections})
        raise BagFormatError(path, f"no {role} topic {topic!r} in the bag; its topics: {', '.join(have) or 'none'}")
    bad = sorted({c.msgtype for c in conns if c.msgtype not in types})
    if bad:
        raise BagFormatError(
            path, f"{role} topic {topic!r} holds {', '.join(bad)}, expected {' or '.join(types)}", topic=topic
        )
    return conns


def _read_messages(path: Path, reader, conns: list, strict: bool, bad: list, handle) -> None:
    """Deserialise every message of ``conns`` in bag order and pass ``(topic, index, msgtype, msg)`` to
    ``handle``; message errors and storage failures as the :mod:`ogm_ppl.datasets.rosbag` docstring says."""
    counter: dict[str, int] = defaultdict(int)
    it = reader.messages(connections=conns)
    last = ("", -1)
    while True:
        try:
            item = next(it)
        except StopIteration:
            return
        except (MemoryError, RecursionError):
            raise BagFormatError(path, "the file is corrupted (implausible sizes)") from None
        except Exception as e:  # the storage failed part way (truncated / corrupted file)
            text = " ".join(str(e).split())[:300] or type(e).__name__
            where = f" after message {last[1]} of {last[0]}" if last[1] >= 0 else " before the first message"
            if strict:
                raise BagFormatError(path, f"storage error{where}: {text}") from None
            bad.append(("", -1, f"reading stopped{where}: {text}"))
            return
        conn, _, raw = item
        index = counter[conn.topic]
        counter[conn.topic] += 1
        last = (conn.topic, index)
        try:
            try:
                msg = reader.deserialize(raw, conn.msgtype)
            except Exception as e:
                raise _MsgError("message", f"cannot decode {conn.msgtype} ({' '.join(str(e).split())[:200]})") from None
            handle(conn.topic, index, conn.msgtype, msg)
        except _MsgError as e:
            if strict:
                raise BagFormatError(path, e.message, topic=conn.topic, index=index, field=e.field) from None
            bad.append((conn.topic, index, f"field {e.field!r}: {e.message}"))
