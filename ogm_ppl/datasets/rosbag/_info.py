"""What a bag holds, without poses: storage, topics and the laser geometry of a scan topic."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from ogm_ppl.datasets.rosbag._errors import _library_errors
from ogm_ppl.datasets.rosbag._messages import (
    LASER_SCAN,
    POSE_TYPES,
    TF_MESSAGE,
    _connections,
    _read_messages,
    _scan_record,
)
from ogm_ppl.datasets.rosbag._open import _open_reader


def bag_info(
    path: str | os.PathLike, scan_topic: str | None = None, *, laser: bool = True, strict: bool = True
) -> dict:
    """What a bag holds, without poses: its storage, topics, and the laser geometry of ``scan_topic``
    (default: the bag's only LaserScan topic, if it has one): scans, beam counts, angular increments,
    first and last beam angles, ``range_min`` / ``range_max`` values, the no-return beams (NaN, +Inf,
    ``>= range_max``), the stamps' duration and the scan rate; and the candidate pose sources. Malformed
    scan messages are counted, not raised (``bad_scans``). Angles in radians, ranges in metres.
    ``laser=False``: the storage and topics only; ``strict=False``: a ROS 1 bag without its index is read
    record by record (:func:`read_bag`)."""
    path = Path(path)
    with _open_reader(path, lenient=not strict) as (reader, kind):
        with _library_errors(path, "cannot list the topics"):
            topics = sorted((n, str(i.msgtype), int(i.msgcount)) for n, i in reader.topics.items())  # type: ignore[attr-defined]
        lasers = [t for t, typ, _ in topics if typ == LASER_SCAN]
        info: dict = {
            "storage": kind,
            "topics": [{"topic": t, "type": typ, "messages": n} for t, typ, n in topics],
            "laser_topics": lasers,
            "pose_topics": [t for t, typ, _ in topics if typ in POSE_TYPES],
            "tf": any(t in ("/tf", "/tf_static") and typ == TF_MESSAGE for t, typ, _ in topics),
        }
        if not laser:
            return info
        if scan_topic is None:
            if len(lasers) != 1:
                return info
            scan_topic = lasers[0]
        conns = _connections(path, reader, scan_topic, (LASER_SCAN,), "scan")
        recs: list[tuple] = []
        bad: list[tuple[str, int, str]] = []
        _read_messages(path, reader, conns, False, bad, lambda t, i, m, msg: recs.append(_scan_record(msg, "decimal")))
    info["scan_topic"] = scan_topic
    info["scans"] = len(recs)
    info["bad_scans"] = len(bad)
    if not recs:
        return info
    n = np.array([len(r[6]) for r in recs])
    inc = np.array([r[3] for r in recs])
    first = np.array([r[2] for r in recs])
    last = first + inc * (n - 1)
    stamps = np.array([r[0] for r in recs], dtype=np.int64) / 1e9
    thr = np.array([r[5] for r in recs])
    no_ret = sum(int((np.isnan(r[6]) | (r[6] >= np.float32(r[5]))).sum()) for r in recs)
    span = float(stamps.max() - stamps.min())
    info.update(
        beams_per_scan=sorted({int(v) for v in n}),
        angle_increment=sorted({float(v) for v in inc})[:10],
        first_angle=float(first.min()),
        last_angle=float(last.max()),
        field_of_view=float((last - first).max()),
        range_min=sorted({float(r[4]) for r in recs})[:10],
        range_max=sorted({float(v) for v in thr})[:10],
        no_return_beams=no_ret,
        beams=int(n.sum()),
        duration=span,
        scan_rate_hz=(len(recs) - 1) / span if span > 0 else None,
        frames=sorted({r[1] for r in recs}),
    )
    return info
