"""Writing scans and poses as a ROS 1 or ROS 2 bag with ``rosbags``' own writers (tests, examples)."""

from __future__ import annotations

import math
import os
import shutil
import tempfile
from pathlib import Path

import numpy as np

from ogm_ppl.datasets.rosbag._messages import (
    LASER_SCAN,
    ODOMETRY,
    POSE_COV_STAMPED,
    POSE_STAMPED,
    POSE_TYPES,
    TF_MESSAGE,
)
from ogm_ppl.scans import Scans

STORAGES = ("ros1", "sqlite3", "mcap")


def typestore(storage: str):
    """The ``rosbags`` typestore to write a bag of ``storage`` with: ROS 1 Noetic (with
    ``tf2_msgs/TFMessage``, which its store lacks) or ROS 2 Humble."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    if storage != "ros1":
        return get_typestore(Stores.ROS2_HUMBLE)
    ts = get_typestore(Stores.ROS1_NOETIC)
    if TF_MESSAGE not in ts.fielddefs:
        ts.register(get_types_from_msg("geometry_msgs/TransformStamped[] transforms", TF_MESSAGE))
    return ts


def write_bag(
    path: str | os.PathLike,
    scans: Scans,
    stamps: np.ndarray,
    *,
    storage: str = "ros1",
    scan_topic: str = "/scan",
    pose_topic: str = "/odom",
    pose_type: str = ODOMETRY,
    tf: bool = False,
    laser_offset: tuple[float, float, float] = (0.0, 0.0, 0.0),
    laser_height: float = 0.0,
    map_to_odom: tuple[float, float, float] = (0.0, 0.0, 0.0),
    map_frame: str = "map",
    laser_frame: str = "laser",
) -> Path:
    """Write ``scans`` as a bag that :func:`read_bag` reads back to the same scans (tests, examples).

    Each scan becomes a LaserScan at ``stamps[s]`` (seconds): ``angle_min = angles[s, 0]``, increment
    ``angles[s, 1] - angles[s, 0]`` (the angles must be evenly spaced), ``range_min = scans.min_range``,
    ``range_max = scans.max_range``; a max-range reading is written as ``range_max`` and an invalid beam as
    NaN (both no-return in the bag). The pose goes to ``pose_topic`` (``pose_type`` one of
    :data:`POSE_TYPES`) as the robot pose ``laser pose (x) laser_offset^-1``; with ``tf=True`` to ``/tf``
    instead (``map -> odom`` = ``map_to_odom`` and ``odom -> base_link`` with each scan) and the laser
    mounting ``base_link -> laser_frame`` (``laser_offset``, ``laser_height``) to ``/tf_static``.

    The bag is written beside ``path`` and swapped in, replacing a bag written there before (a folder that
    is no ROS 2 bag is refused): an interrupted write leaves the old bag or the new one.

    Args:
        storage: ``"ros1"`` (a ``.bag`` file), ``"sqlite3"`` or ``"mcap"`` (a ROS 2 bag folder).
    """
    from rosbags.rosbag1 import Writer as Writer1
    from rosbags.rosbag2 import StoragePlugin
    from rosbags.rosbag2 import Writer as Writer2

    if storage not in STORAGES:
        raise ValueError(f"write_bag: storage must be one of {STORAGES}, got {storage!r}")
    if pose_type not in POSE_TYPES:
        raise ValueError(f"write_bag: pose_type must be one of {POSE_TYPES}, got {pose_type!r}")
    stamps = np.asarray(stamps, dtype=np.float64)
    if stamps.shape != (scans.num_scans,) or not np.isfinite(stamps).all() or (stamps < 0).any():
        raise ValueError(f"write_bag: need {scans.num_scans} finite stamps >= 0, got shape {stamps.shape}")
    B = scans.beams_per_scan
    step = scans.angles[:, 1] - scans.angles[:, 0] if B > 1 else np.zeros(scans.num_scans)
    if B > 1 and not np.allclose(scans.angles, scans.angles[:, :1] + step[:, None] * np.arange(B), atol=1e-9):
        raise ValueError("write_bag: beam angles must be evenly spaced in every scan")
    path = Path(path)
    ros1 = storage == "ros1"
    ts = typestore(storage)
    T = ts.types
    ns = np.round(stamps * 1e9).astype(np.int64)
    bag_ns = np.maximum.accumulate(ns)  # receive times never go back; header stamps may (the Intel log's do)
    ox, oy, oyaw = laser_offset
    mx, my, myaw = map_to_odom
    # robot pose = laser pose (x) offset^-1
    yaw_r = scans.poses[:, 2] - oyaw
    c, s = np.cos(yaw_r), np.sin(yaw_r)
    rx = scans.poses[:, 0] - (ox * c - oy * s)
    ry = scans.poses[:, 1] - (ox * s + oy * c)

    def header(t: int, frame: str, seq: int = 0):
        stamp = T["builtin_interfaces/msg/Time"](sec=int(t // 1_000_000_000), nanosec=int(t % 1_000_000_000))
        if ros1:
            return T["std_msgs/msg/Header"](seq=seq, stamp=stamp, frame_id=frame)
        return T["std_msgs/msg/Header"](stamp=stamp, frame_id=frame)

    def quat(yaw: float):
        return T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=math.sin(yaw / 2), w=math.cos(yaw / 2))

    def pose(x: float, y: float, yaw: float, z: float = 0.0):
        return T["geometry_msgs/msg/Pose"](position=T["geometry_msgs/msg/Point"](x=x, y=y, z=z), orientation=quat(yaw))

    def transform(t: int, parent: str, child: str, x: float, y: float, z: float, yaw: float):
        v = T["geometry_msgs/msg/Vector3"](x=x, y=y, z=z)
        return T["geometry_msgs/msg/TransformStamped"](
            header=header(t, parent),
            child_frame_id=child,
            transform=T["geometry_msgs/msg/Transform"](translation=v, rotation=quat(yaw)),
        )

    def ser(msg, typ: str):
        return ts.serialize_ros1(msg, typ) if ros1 else ts.serialize_cdr(msg, typ)

    valid, is_max = np.asarray(scans.valid), np.asarray(scans.is_max)
    out = np.where(valid & ~is_max, scans.ranges, np.where(is_max, scans.max_range, np.nan)).astype(np.float32)
    base_frame = "base_link"
    if ros1 and path.is_dir():
        raise ValueError(f"write_bag: {path} is a folder; a ROS 1 bag is a file")
    if not ros1 and path.exists() and not (path / "metadata.yaml").is_file():
        raise ValueError(f"write_bag: {path} exists and is not a ROS 2 bag folder (no metadata.yaml); not replacing it")
    target = path
    target.parent.mkdir(parents=True, exist_ok=True)
    # written beside the target, then swapped in: an interrupted write leaves the old bag or the new one
    stage = Path(tempfile.mkdtemp(dir=target.parent, prefix=f".{target.name}.staging-"))
    path = stage / target.name
    if ros1:
        writer: object = Writer1(path)
    else:
        plugin = StoragePlugin.SQLITE3 if storage == "sqlite3" else StoragePlugin.MCAP
        writer = Writer2(path, version=9, storage_plugin=plugin)
    try:
        with writer as w:  # type: ignore[attr-defined]
            c_scan = w.add_connection(scan_topic, LASER_SCAN, typestore=ts)
            if tf:
                c_tf = w.add_connection("/tf", TF_MESSAGE, typestore=ts)
                c_static = w.add_connection("/tf_static", TF_MESSAGE, typestore=ts)
                mount = transform(int(ns.min()), base_frame, laser_frame, ox, oy, laser_height, oyaw)
                w.write(c_static, int(ns.min()), ser(T[TF_MESSAGE](transforms=[mount]), TF_MESSAGE))
            else:
                c_pose = w.add_connection(pose_topic, pose_type, typestore=ts)
            for k in range(scans.num_scans):
                t, tb = int(ns[k]), int(bag_ns[k])
                if tf:
                    # odom -> base_link = (map -> odom)^-1 (x) robot pose
                    c0, s0 = math.cos(myaw), math.sin(myaw)
                    dx, dy = float(rx[k]) - mx, float(ry[k]) - my
                    odom = transform(t, map_frame, "odom", mx, my, 0.0, myaw)
                    link = transform(
                        t, "odom", base_frame, c0 * dx + s0 * dy, -s0 * dx + c0 * dy, 0.0, float(yaw_r[k]) - myaw
                    )
                    w.write(c_tf, tb, ser(T[TF_MESSAGE](transforms=[odom, link]), TF_MESSAGE))
                else:
                    h = header(t, map_frame, k)
                    p = pose(float(rx[k]), float(ry[k]), float(yaw_r[k]))
                    if pose_type == POSE_STAMPED:
                        msg = T[POSE_STAMPED](header=h, pose=p)
                    else:
                        cov = T["geometry_msgs/msg/PoseWithCovariance"](pose=p, covariance=np.zeros(36))
                        if pose_type == POSE_COV_STAMPED:
                            msg = T[POSE_COV_STAMPED](header=h, pose=cov)
                        else:
                            z3 = T["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0)
                            tw = T["geometry_msgs/msg/TwistWithCovariance"](
                                twist=T["geometry_msgs/msg/Twist"](linear=z3, angular=z3), covariance=np.zeros(36)
                            )
                            msg = T[ODOMETRY](header=h, child_frame_id=base_frame, pose=cov, twist=tw)
                    w.write(c_pose, tb, ser(msg, pose_type))
                n = B
                scan = T[LASER_SCAN](
                    header=header(t, laser_frame, k),
                    angle_min=float(scans.angles[k, 0]),
                    angle_max=float(scans.angles[k, 0] + step[k] * (n - 1)),
                    angle_increment=float(step[k]),
                    time_increment=0.0,
                    scan_time=0.0,
                    range_min=float(scans.min_range),
                    range_max=float(scans.max_range),
                    ranges=out[k],
                    intensities=np.zeros(0, dtype=np.float32),
                )
                w.write(c_scan, tb, ser(scan, LASER_SCAN))
        if target.is_dir():  # a bag folder written before: swap, then drop the old one
            os.replace(target, stage / ".old")
        os.replace(path, target)
    finally:
        shutil.rmtree(stage, ignore_errors=True)
    return target
