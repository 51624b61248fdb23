"""The shipped kinds that read a file: ``log`` (a CARMEN log, :func:`~ogm_ppl.datasets.read_carmen`), ``bag`` (a
ROS bag, :func:`~ogm_ppl.datasets.read_bag`) and ``npz`` (an ogm_ppl dataset file,
:func:`~ogm_ppl.datasets.load_dataset`), each with its options declared once."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path
from typing import Any, cast

from ogm_ppl.inputs.kinds import InputData, InputKind, image_kind, register_input_kind
from ogm_ppl.options import Bool, Choice, Float, Int, Kind, Numbers, Optional, ParamError, Text, _Bad, param

__all__ = ["BagOptions", "DatasetFileOptions", "LogOptions"]

#: how a spec names the options the rules between options mention
_SPEC_NAMES = {
    "pose_topic": "pose_topic",
    "tf": "tf = true",
    "pose_step": "pose_step",
    "pose_fraction": "pose_fraction",
}


def _check_thinning(o) -> None:
    if o.pose_step != 1 and o.pose_fraction is not None:
        raise ParamError("pose_fraction", "give {pose_step} or {pose_fraction}, not both", _SPEC_NAMES)


@dataclass(frozen=True)
class _Thinning:
    """Which scans and beams of the input are kept (every k-th, or an evenly spaced fraction)."""

    pose_step: int = param(1, Int(lo=1), "keep every pose_step-th scan", group="thinning")
    pose_fraction: float | None = param(
        None,
        Optional(Float(0, 1, lo_open=True)),
        "keep an evenly spaced fraction in (0, 1] of the scans (Table 6.5 uses 0.1); none: pose_step decides",
        group="thinning",
    )
    beam_step: int = param(1, Int(lo=1), "keep every beam_step-th beam of each scan", group="thinning")

    def check(self) -> None:
        _check_thinning(self)

    def thinning(self) -> dict[str, Any]:
        return {"pose_step": self.pose_step, "pose_fraction": self.pose_fraction, "beam_step": self.beam_step}


_DROP_MAX = Choice("drop", "max")


@dataclass(frozen=True)
class _RangeRules(_Thinning):
    """The range rules a log reader applies to every reading (:mod:`ogm_ppl.datasets.carmen`)."""

    strict: bool = param(
        True,
        Bool(),
        "stop at the first malformed line or message, naming file, line (bag: topic, message) and field; "
        "false: skip it, listed in the record",
        group="reader",
    )
    max_usable_range: float | None = param(
        None,
        Optional(Float(0, lo_open=True)),
        "readings at or beyond it (metres) follow usable_range_rule (the Intel protocol of thesis Section 6.2 is "
        "20); none: keep every reading",
        group="reader",
    )
    usable_range_rule: str = param(
        "drop", _DROP_MAX, "a reading beyond max_usable_range: 'drop' (an invalid beam) or 'max'", group="reader"
    )
    no_return: str = param(
        "drop",
        _DROP_MAX,
        "a no-return sentinel reading: 'drop' (an invalid beam, as in the thesis) or 'max' (a max-range reading "
        "that clears the cells it crosses)",
        group="reader",
    )
    no_return_threshold: float | None = param(
        None,
        Optional(Float(0, lo_open=True)),
        "readings at or above it (metres) are no-return; none: the input's own rule",
        group="reader",
    )
    min_range: float = param(0.0, Float(0), "readings below it (metres) are invalid", group="reader")
    max_range: float | None = param(
        None,
        Optional(Float(0, lo_open=True)),
        "the sensor's maximum range (metres); none: max_usable_range, else the no-return threshold, else just "
        "above the largest reading",
        group="reader",
    )

    def rules(self) -> dict[str, Any]:
        names = ("strict", "max_usable_range", "usable_range_rule", "no_return", "no_return_threshold")
        return {k: getattr(self, k) for k in (*names, "min_range", "max_range")}


class Messages(Kind):
    """The CARMEN laser message types to read: ``"auto"``, one type, or a list of them."""

    def value(self, v):
        from ogm_ppl.datasets.carmen import _LASER_TYPES

        if v == "auto" or v in _LASER_TYPES:
            return v
        if isinstance(v, (list, tuple)) and v and all(x in _LASER_TYPES for x in v) and len(set(v)) == len(v):
            return list(v)
        raise _Bad(f"must be 'auto', a laser message type ({', '.join(_LASER_TYPES)}) or a list of them, got {v!r}")

    def text(self, s):
        return self.value(s if "," not in s else [x.strip() for x in s.split(",")])

    def describe(self):
        return "'auto', FLASER, ROBOTLASER1 or a list"


@dataclass(frozen=True)
class LogOptions(_RangeRules):
    """The options of a CARMEN log (:func:`~ogm_ppl.datasets.read_carmen`)."""

    messages: object = param(
        "auto",
        Messages(),
        "laser message types read: 'auto' (ROBOTLASER1 if the log has any, else FLASER), one type or a list",
        group="reader",
    )
    apply_laser_offset: bool = param(
        False,
        Bool(),
        "read FLASER x y theta as the robot pose, moved forward by PARAM robot_frontlaser_offset (CARMEN writes "
        "the laser pose there)",
        group="reader",
    )


def _read_log(path: Path, o: LogOptions) -> InputData:
    from ogm_ppl.datasets.carmen import read_carmen

    messages = o.messages if isinstance(o.messages, str) else tuple(cast("list[str]", o.messages))
    log = read_carmen(path, **o.rules(), **o.thinning(), messages=messages, apply_laser_offset=o.apply_laser_offset)
    return InputData("log", path, log.scans, settings=log.settings, record=log)


@dataclass(frozen=True)
class BagOptions(_RangeRules):
    """The options of a ROS bag (:func:`~ogm_ppl.datasets.read_bag`): the scan topic and one pose source."""

    scan_topic: str | None = param(None, Optional(Text()), "the sensor_msgs/LaserScan topic (required)")
    pose_topic: str | None = param(
        None,
        Optional(Text()),
        "poses from a nav_msgs/Odometry, geometry_msgs/PoseStamped or PoseWithCovarianceStamped topic (or tf)",
    )
    tf: bool = param(
        False, Bool(), "poses from /tf + /tf_static: map_frame -> ... -> the scans' frame (laser mounting included)"
    )
    map_frame: str | None = param(None, Optional(Text()), "the world frame of tf (none: map)")
    laser_offset: object = param(
        None,
        Optional(Numbers(3, "[x, y, yaw] (metres, radians)")),
        "the laser in the robot frame of pose_topic, metres and radians (none: 0 0 0)",
    )
    pose_tolerance: float = param(
        0.1, Float(0), "drop scans more than this many seconds from the pose samples around them"
    )
    widen: str = param(
        "decimal",
        Choice("decimal", "binary"),
        "how float32 fields become float64: 'decimal' (their shortest decimal) or 'binary' (exactly)",
        group="reader",
    )

    def check(self) -> None:
        if self.scan_topic is None:
            raise ParamError("scan_topic", "is required")
        if self.pose_topic is not None and self.tf:
            raise ParamError("pose_topic", "give {pose_topic} or {tf}, one of them", _SPEC_NAMES)
        if self.pose_topic is None and not self.tf:
            raise ParamError("tf", "give {pose_topic} or {tf}, one of them", _SPEC_NAMES)
        if self.map_frame is not None and not self.tf:
            raise ParamError("map_frame", "applies to {tf}", _SPEC_NAMES)
        if self.laser_offset is not None and self.tf:
            raise ParamError(
                "laser_offset", "applies to {pose_topic}; with {tf} the mounting comes from /tf_static", _SPEC_NAMES
            )
        _check_thinning(self)


def _read_bag(path: Path, o: BagOptions) -> InputData:
    from ogm_ppl.datasets.rosbag import read_bag

    assert o.scan_topic is not None  # BagOptions.check
    bag = read_bag(
        path,
        o.scan_topic,
        o.pose_topic,
        tf=o.tf,
        map_frame=o.map_frame or "map",
        laser_offset=cast("tuple[float, float, float]", tuple(cast("list[float]", o.laser_offset or [0.0, 0.0, 0.0]))),
        pose_tolerance=o.pose_tolerance,
        widen=o.widen,
        **o.rules(),
        **o.thinning(),
    )
    return InputData("bag", path, bag.scans, settings=bag.settings, record=bag)


def _is_bag(path: Path, head: bytes) -> bool:
    from ogm_ppl.datasets.rosbag import bag_kind

    return bag_kind(path) is not None


@dataclass(frozen=True)
class DatasetFileOptions(_Thinning):
    """The options of an ogm_ppl dataset file (:func:`~ogm_ppl.datasets.load_dataset`): its thinning."""


def _read_npz(path: Path, o: DatasetFileOptions) -> InputData:
    from ogm_ppl.datasets.dataset_file import load_dataset

    ds = load_dataset(path)
    scans = ds.scans
    if dataclasses.astuple(o) != (1, None, 1):
        scans = scans.subsample(o.pose_step, o.beam_step, o.pose_fraction)
    return InputData("npz", path, scans, ds.grid, ds.truth, dict(ds.settings or {}), ds)


register_input_kind(
    InputKind(
        "log",
        LogOptions,
        _read_log,
        "a CARMEN log, plain or gzip (read_carmen)",
        noun="CARMEN log",
        what="a CARMEN log, plain or gzip",
        label="carmen",
        detect=lambda path, head: path.is_file() and image_kind(head) is None,
        detect_last=True,
    )
)
register_input_kind(
    InputKind(
        "bag",
        BagOptions,
        _read_bag,
        "a ROS 1 or ROS 2 bag: a LaserScan topic and its poses (read_bag)",
        noun="ROS bag",
        what="a ROS 1 .bag file, or a ROS 2 bag folder or its .db3 / .mcap",
        detect=_is_bag,
    )
)
register_input_kind(
    InputKind(
        "npz",
        DatasetFileOptions,
        _read_npz,
        "an ogm_ppl dataset file: scans, and a grid and truth where it has them (load_dataset)",
        noun="dataset file",
        what="an ogm_ppl dataset .npz",
        label="dataset",
        detect=lambda path, head: head[:2] == b"PK",
    )
)
