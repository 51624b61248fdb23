"""Reading the Intel log as ROS bags: ROS 1 ``.bag``, ROS 2 sqlite3 and ROS 2 MCAP, against ``read_carmen``
on the same scans in the same run.

The log's 910 FLASER scans and their corrected poses are written with ``write_bag`` (rosbags' own writers;
LaserScan + ``nav_msgs/Odometry``, and a ``/tf`` + ``/tf_static`` bag with a laser mounting), then each is
read with ``read_bag(..., max_usable_range=20.0)`` (the Section 6.2 protocol) and timed (best of 3 after a
warm-up); the ratio is bag read time / ``read_carmen`` read time. The scans read are checked against the
CARMEN reader's (ranges, angles and masks bit for bit, poses to 1e-12). Writes out/bench/bench_rosbag.json.
"""

from __future__ import annotations

import os
import shutil
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, os.path.dirname(__file__))
from _common import best_time, peak_rss_mb, write_json

from ogm_ppl.datasets import read_bag, read_carmen
from ogm_ppl.datasets.rosbag import write_bag
from ogm_ppl.experiment.headline import INTEL_LOG, find_shared_file


def _size(p: Path) -> int:
    return sum(f.stat().st_size for f in p.rglob("*") if f.is_file()) if p.is_dir() else p.stat().st_size


def main() -> dict:
    log_path = find_shared_file(INTEL_LOG)
    if log_path is None:
        sys.exit(f"bench_rosbag: the Intel log ({INTEL_LOG}) is not under $OGM_PPL_DATA or ../shared/data")
    raw = read_carmen(log_path, no_return="max")  # the sentinels kept as the log holds them
    ref = read_carmen(log_path, max_usable_range=20.0)
    t_carmen = best_time(lambda: read_carmen(log_path, max_usable_range=20.0), repeat=3)
    tmp = Path(tempfile.mkdtemp(prefix="bench_rosbag."))
    rows = []
    try:
        cases = [
            ("ros1", "pose topic", {"pose_topic": "/odom"}, {}),
            ("sqlite3", "pose topic", {"pose_topic": "/odom"}, {}),
            ("mcap", "pose topic", {"pose_topic": "/odom"}, {}),
            ("ros1", "tf chain", {"tf": True}, {"tf": True, "laser_offset": (0.12, -0.03, 0.07), "laser_height": 0.3}),
            ("mcap", "tf chain", {"tf": True}, {"tf": True, "laser_offset": (0.12, -0.03, 0.07), "laser_height": 0.3}),
        ]
        print(f"{'storage':>8} {'poses':>11} {'size (MB)':>10} {'read (s)':>9} {'/ read_carmen':>14}  same scans")
        for i, (storage, poses, read_kw, write_kw) in enumerate(cases):
            p = tmp / (f"b{i}.bag" if storage == "ros1" else f"b{i}")
            write_bag(p, raw.scans, raw.timestamps, storage=storage, **write_kw)
            t = best_time(lambda: read_bag(p, "/scan", max_usable_range=20.0, **read_kw), repeat=3)  # noqa: B023
            s, r = read_bag(p, "/scan", max_usable_range=20.0, **read_kw).scans, ref.scans
            dyaw = np.mod(s.poses[:, 2] - r.poses[:, 2] + np.pi, 2 * np.pi) - np.pi
            same = bool(
                all(np.array_equal(getattr(s, k), getattr(r, k)) for k in ("ranges", "angles", "valid", "is_max"))
                and np.abs(s.poses[:, :2] - r.poses[:, :2]).max() <= 1e-12
                and np.abs(dyaw).max() <= 1e-12
            )
            rows.append(
                {
                    "storage": storage,
                    "poses": poses,
                    "bytes": _size(p),
                    "read_s": t,
                    "ratio_vs_read_carmen": t / t_carmen,
                    "scans": s.num_scans,
                    "same_scans_as_read_carmen": same,
                }
            )
            print(f"{storage:>8} {poses:>11} {_size(p) / 1e6:>10.2f} {t:>9.3f} {t / t_carmen:>14.2f}  {same}")
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    print(f"read_carmen: {t_carmen:.3f} s for {ref.scans.num_scans} scans x {ref.scans.beams_per_scan} beams")
    payload = {
        "log": INTEL_LOG,
        "scans": ref.scans.num_scans,
        "beams_per_scan": ref.scans.beams_per_scan,
        "read_carmen_s": t_carmen,
        "bags": rows,
        "peak_rss_mb": peak_rss_mb(),
    }
    print(f"wrote {write_json('bench_rosbag', payload)}")
    return payload


if __name__ == "__main__":
    main()
