"""``ogm-ppl info LOG|BAG|DATASET``: what a log, bag or dataset file holds, read with the reader options."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from ogm_ppl.scans import Scans
from ogm_ppl.cli._common import (
    _jsonable,
)
from ogm_ppl.cli._input import (
    _add_bag_options,
    _add_reader_options,
    _input_values,
    _parse_options,
)


def add_parser(sub) -> None:
    """The ``info`` subcommand's options."""
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
    from ogm_ppl.datasets.rosbag import bag_info
    from ogm_ppl.inputs import read_input

    path = args.input
    kind, values = _input_values(args, path, pose_required=False)
    if kind.name == "bag":
        info = bag_info(path, values["scan_topic"], strict=values.get("strict", True))
        r: dict = {"input": str(path), "kind": "bag", "storage": info["storage"], "topics": info["topics"]}
        r["scan_topic"] = info.get("scan_topic")
        r["laser_frames"] = info.get("frames")
        r["message_range_min_m"] = info.get("range_min")
        r["message_range_max_m"] = info.get("range_max")
        r["no_return_rule"] = "NaN, +Inf or >= range_max of the message" + (
            f", or >= {args.no_return_threshold} m" if getattr(args, "no_return_threshold", None) else ""
        )
        r["no_return_beams_in_bag"] = info.get("no_return_beams")
        if "pose_topic" not in values and not values.get("tf"):  # the geometry from the scan messages alone
            if info.get("scans"):
                r["scans"] = info["scans"]
                r["beams_per_scan"] = info["beams_per_scan"]
                r["angular_increment_deg"] = [_deg(v) for v in info["angle_increment"]]
                r["field_of_view_deg"] = _deg(info["field_of_view"])
                r["first_beam_deg"], r["last_beam_deg"] = _deg(info["first_angle"]), _deg(info["last_angle"])
                r["duration_s"], r["scan_rate_hz"] = info["duration"], info["scan_rate_hz"]
            r["poses"] = "none found: give --pose-topic or --tf for the extent and the pose rate"
            return r
        bag = read_input("bag", path, _parse_options(kind, values, path)).record
        r.update(_scan_stats(bag.scans))
        r["counts"] = bag.counts
        r["poses"] = bag.pose_source
        r["duration_s"] = float(np.ptp(bag.timestamps)) if len(bag.timestamps) else 0.0
        r["scan_rate_hz"] = _rate(bag.scans.num_scans, bag.timestamps)
        r["pose_rate_hz"] = _rate(len(bag.pose_timestamps), bag.pose_timestamps)
        r["bad_messages"] = len(bag.bad_messages)
        return r
    data = read_input(kind.name, path, _parse_options(kind, values, path))
    if kind.name != "log":  # a dataset file, or a kind of one's own: what its scans show
        r = {"input": str(path), "kind": kind.report_label, **_scan_stats(data.scans)}
        if kind.name == "npz":
            grid = data.grid
            r["grid"] = None if grid is None else {"shape": list(grid.shape), "resolution_m": grid.resolution}
            r["truth"] = data.truth is not None
        r["duration_s"] = r["scan_rate_hz"] = r["pose_rate_hz"] = None  # a dataset file keeps no stamps
        return r
    log = data.record
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


def run(args) -> int:
    """``ogm-ppl info``: lines or JSON."""
    r = cmd_info(args)
    print(json.dumps(_jsonable(r), indent=2) if args.json else _info_text(r))
    return 0
