"""ROS bag reader: bags written with rosbags' own writers (ROS 1, ROS 2 sqlite3, ROS 2 MCAP) from a slice
of the Intel log read back to the CARMEN reader's scans and maps; the REP 117 beam rules, pose
interpolation, transform chains, strict and lenient errors, and corrupted files."""

import math
import time
from pathlib import Path

import numpy as np
import pytest

from ogm_ppl.datasets import read_bag, read_carmen
from ogm_ppl.datasets.rosbag import (
    LASER_SCAN,
    POSE_COV_STAMPED,
    POSE_STAMPED,
    TF_MESSAGE,
    BagFormatError,
    bag_kind,
    bag_topics,
    typestore,
    write_bag,
)
from ogm_ppl.datasets.rosbag._numbers import _angle64, _widen_array
from ogm_ppl.inference import evidence_grid_from_scans
from ogm_ppl.models import delta_by_name
from ogm_ppl.scans import Scans

DATA = Path(__file__).resolve().parents[3] / "shared" / "data"
INTEL = DATA / "intel-lab" / "intel-corrected.log.gz"
needs_data = pytest.mark.skipif(not INTEL.exists(), reason="shared data not present")
STORAGES = ("ros1", "sqlite3", "mcap")
# scans 280..320 of the Intel log: their header stamps go back once (scan 295), as the log's do
SLICE = slice(280, 320)
EPS_YAW = 8 * np.finfo(float).eps * np.pi  # yaw through a quaternion and back: a few ulps of pi


def _slice(scans: Scans, sl: slice) -> Scans:
    return Scans(
        scans.poses[sl],
        scans.angles[sl],
        scans.ranges[sl],
        scans.max_range,
        over_range="max",
        valid=scans.valid[sl],
        min_range=scans.min_range,
    )


def _bag_path(tmp: Path, storage: str, name: str = "intel") -> Path:
    return tmp / (f"{name}.bag" if storage == "ros1" else f"{name}_{storage}")


@pytest.fixture(scope="module")
def intel():
    """The raw slice (no-return sentinels kept as max-range readings, as the log holds them) and its stamps."""
    if not INTEL.exists():
        pytest.skip("shared data not present")
    raw = read_carmen(INTEL, no_return="max")
    return _slice(raw.scans, SLICE), raw.timestamps[SLICE]


@pytest.fixture(scope="module")
def bags(intel, tmp_path_factory):
    tmp = tmp_path_factory.mktemp("bags")
    scans, stamps = intel
    return {s: write_bag(_bag_path(tmp, s), scans, stamps, storage=s) for s in STORAGES}


def _carmen(**kw) -> Scans:
    return _slice(read_carmen(INTEL, **kw).scans, SLICE)


def _wrap(a):
    return np.mod(a + np.pi, 2 * np.pi) - np.pi


def _assert_same_scans(a: Scans, b: Scans, yaw_tol: float = EPS_YAW, xy_tol: float = 0.0) -> None:
    for name in ("angles", "ranges", "valid", "is_max"):
        assert np.array_equal(getattr(a, name), getattr(b, name)), name
    assert a.max_range == b.max_range and a.min_range == b.min_range
    assert np.abs(a.poses[:, :2] - b.poses[:, :2]).max() <= xy_tol
    assert np.abs(_wrap(a.poses[:, 2] - b.poses[:, 2])).max() <= yaw_tol


def _map(scans: Scans, grid):
    return evidence_grid_from_scans(grid, scans, delta_by_name("haehnel")).probabilities.numpy()


# ------------------------------------------------------------------------- the Intel log as bags
@needs_data
@pytest.mark.parametrize("storage", STORAGES)
@pytest.mark.parametrize(
    "options",
    [{}, {"max_usable_range": 20.0}, {"no_return": "max"}, {"max_usable_range": 20.0, "usable_range_rule": "max"}],
    ids=["default", "usable20", "no_return_max", "usable20_max"],
)
def test_bag_scans_equal_the_carmen_readers(bags, storage, options):
    """Ranges, beam angles, masks and range limits bit for bit; x, y exactly; yaw to a few ulps (it goes
    through a quaternion)."""
    log = read_bag(bags[storage], "/scan", "/odom", **options)
    ref = read_carmen(INTEL, **options)
    _assert_same_scans(log.scans, _slice(ref.scans, SLICE))
    assert log.storage == storage and log.counts["no_pose"] == 0 and log.counts["scans_read"] == 40
    assert np.array_equal(log.message_indices, np.arange(40))  # bag order, though the stamps go back once
    assert np.array_equal(log.timestamps, np.round(ref.timestamps[SLICE] * 1e9) / 1e9)


@needs_data
@pytest.mark.parametrize("storage", STORAGES)
def test_map_of_each_bag_equals_the_carmen_map(bags, storage):
    ref = _carmen(max_usable_range=20.0)
    log = read_bag(bags[storage], "/scan", "/odom", max_usable_range=20.0)
    grid = log.grid(0.1)
    assert np.array_equal(_map(log.scans, grid), _map(ref, grid))


@needs_data
@pytest.mark.parametrize(("storage", "pose_type"), [("ros1", POSE_STAMPED), ("sqlite3", POSE_COV_STAMPED)])
def test_pose_message_types(intel, tmp_path, storage, pose_type):
    scans, stamps = intel
    p = write_bag(_bag_path(tmp_path, storage), scans, stamps, storage=storage, pose_topic="/pose", pose_type=pose_type)
    _assert_same_scans(read_bag(p, "/scan", "/pose").scans, _carmen())


@needs_data
@pytest.mark.parametrize("storage", ["ros1", "mcap"])
def test_tf_chain_with_a_laser_offset_maps_like_the_pose_topic(intel, bags, tmp_path, storage):
    """map -> odom -> base_link (dynamic, /tf) -> laser (static, /tf_static, mounted 0.3 m up, ahead,
    to the side and turned): the laser poses and the map equal the pose-topic bag's."""
    scans, stamps = intel
    p = write_bag(
        _bag_path(tmp_path, storage, "tf"),
        scans,
        stamps,
        storage=storage,
        tf=True,
        laser_offset=(0.12, -0.03, 0.07),
        laser_height=0.3,
        map_to_odom=(0.4, -0.25, 0.3),
    )
    assert {t for t, _, _ in bag_topics(p)} == {"/scan", "/tf", "/tf_static"}
    tf_log = read_bag(p, "/scan", tf=True, max_usable_range=20.0)
    topic_log = read_bag(bags[storage], "/scan", "/odom", max_usable_range=20.0)
    _assert_same_scans(tf_log.scans, topic_log.scans, yaw_tol=1e-12, xy_tol=1e-12)
    grid = topic_log.grid(0.1)
    assert np.array_equal(_map(tf_log.scans, grid), _map(topic_log.scans, grid))
    assert tf_log.pose_source == "tf" and tf_log.counts["no_pose"] == 0


@needs_data
def test_laser_offset_on_a_pose_topic(intel, tmp_path):
    scans, stamps = intel
    off = (0.2, 0.05, -0.1)
    p = write_bag(tmp_path / "off.bag", scans, stamps, laser_offset=off)
    _assert_same_scans(read_bag(p, "/scan", "/odom", laser_offset=off).scans, _carmen(), yaw_tol=1e-12, xy_tol=1e-12)
    robot = read_bag(p, "/scan", "/odom").scans.poses
    assert np.abs(robot[:, :2] - _carmen().poses[:, :2]).max() > 0.1  # without the offset: the robot's pose


# ------------------------------------------------------------------------- hand-written bags
def _write(path: Path, storage: str, messages: list[tuple[str, str, int, dict]]) -> Path:
    """A bag of ``(topic, type, stamp ns, fields)``: LaserScan fields (ranges, angle_*, range_*) or a
    pose ``(x, y, yaw)`` / ``tf`` list of ``(parent, child, x, y, yaw)``; header stamp = bag time."""
    from rosbags.rosbag1 import Writer as W1
    from rosbags.rosbag2 import StoragePlugin
    from rosbags.rosbag2 import Writer as W2

    ros1 = storage == "ros1"
    ts = typestore(storage)
    T = ts.types

    def hdr(t, frame):
        st = T["builtin_interfaces/msg/Time"](sec=t // 10**9, nanosec=t % 10**9)
        return T["std_msgs/msg/Header"](**({"seq": 0} if ros1 else {}), stamp=st, frame_id=frame)

    def q(yaw, norm=1.0, roll=0.0):  # roll about x, then yaw about z
        cy, sy, cr, sr = math.cos(yaw / 2), math.sin(yaw / 2), math.cos(roll / 2), math.sin(roll / 2)
        return T["geometry_msgs/msg/Quaternion"](x=norm * cy * sr, y=norm * sy * sr, z=norm * sy * cr, w=norm * cy * cr)

    def build(typ, t, f):
        if typ == LASER_SCAN:
            r = np.asarray(f["ranges"], dtype=np.float32)
            inc = f.get("angle_increment", 0.1)
            amin = f.get("angle_min", 0.0)
            return T[LASER_SCAN](
                header=hdr(t, f.get("frame", "laser")),
                angle_min=amin,
                angle_max=f.get("angle_max", amin + inc * (len(r) - 1)),
                angle_increment=inc,
                time_increment=0.0,
                scan_time=0.0,
                range_min=f.get("range_min", 0.0),
                range_max=f.get("range_max", 10.0),
                ranges=r,
                intensities=np.zeros(0, np.float32),
            )
        if typ == TF_MESSAGE:
            out = []
            for parent, child, x, y, yaw, *roll in f["tf"]:
                v = T["geometry_msgs/msg/Vector3"](x=x, y=y, z=0.0)
                rot = q(yaw, roll=roll[0] if roll else 0.0)
                out.append(
                    T["geometry_msgs/msg/TransformStamped"](
                        header=hdr(t, parent),
                        child_frame_id=child,
                        transform=T["geometry_msgs/msg/Transform"](translation=v, rotation=rot),
                    )
                )
            return T[TF_MESSAGE](transforms=out)
        x, y, yaw = f["pose"]
        pose = T["geometry_msgs/msg/Pose"](
            position=T["geometry_msgs/msg/Point"](x=x, y=y, z=0.0), orientation=q(yaw, f.get("qnorm", 1.0))
        )
        return T[POSE_STAMPED](header=hdr(t, "map"), pose=pose)

    w = W1(path) if ros1 else W2(path, version=9, storage_plugin=StoragePlugin[storage.upper()])
    with w:
        conns = {}
        for topic, typ, t, f in messages:
            if topic not in conns:
                conns[topic] = w.add_connection(topic, typ, typestore=ts)
            m = build(typ, t, f)
            w.write(conns[topic], t, ts.serialize_ros1(m, typ) if ros1 else ts.serialize_cdr(m, typ))
    return path


S = 10**9


def _pose(t, x, y, yaw, **kw):
    return ("/pose", POSE_STAMPED, t, {"pose": (x, y, yaw), **kw})


def _scan(t, ranges=(1.0, 2.0), **kw):
    return ("/scan", LASER_SCAN, t, {"ranges": ranges, **kw})


@pytest.mark.parametrize("storage", STORAGES)
def test_rep117_beams_follow_the_carmen_rules(tmp_path, storage):
    """NaN, +Inf and ranges >= range_max are no-return (dropped, or max-range readings with
    no_return='max'); -Inf and ranges below range_min are below minimum; the usable-range rule after."""
    r = [1.0, np.nan, np.inf, -np.inf, 0.05, 10.0, 12.0, 7.5]
    p = _write(
        _bag_path(tmp_path, storage, "b"), storage, [_pose(0, 0, 0, 0), _scan(0, r, range_min=0.1), _pose(S, 0, 0, 0)]
    )
    log = read_bag(p, "/scan", "/pose")
    assert log.scans.valid.tolist() == [[True, False, False, False, False, False, False, True]]
    assert log.max_range == 10.0 and log.scans.ranges[0, [0, 7]].tolist() == [1.0, 7.5]
    c = log.counts
    assert (c["no_return"], c["below_min"], c["valid"], c["beams"]) == (4, 2, 2, 8)
    m = read_bag(p, "/scan", "/pose", no_return="max", max_usable_range=5.0, usable_range_rule="max")
    assert m.scans.valid.tolist() == [[True, True, True, False, False, True, True, True]]
    assert m.scans.is_max.tolist() == [[False, True, True, False, False, True, True, True]]
    assert m.max_range == 5.0 and m.counts["beyond_usable"] == 1
    t = read_bag(p, "/scan", "/pose", no_return_threshold=7.0)
    assert t.scans.valid[0].tolist() == [True] + [False] * 7


def test_pose_interpolation_linear_shortest_arc_and_tolerance(tmp_path):
    """Scans between pose samples get the linear position and the shortest-arc yaw (through +-pi);
    scans beyond the samples or farther than pose_tolerance from them are dropped and counted."""
    msgs = [
        _pose(0, 0.0, 0.0, 3.0),
        _scan(S // 4),
        _pose(S // 2, 1.0, -2.0, -3.0),
        _scan(S // 2),
        _pose(5 * S, 3.0, 0.0, 0.0),
        _scan(3 * S),  # 2.5 s from both samples
        _scan(6 * S),  # after the last sample
    ]
    p = _write(tmp_path / "i.bag", "ros1", msgs)
    log = read_bag(p, "/scan", "/pose", pose_tolerance=0.6)
    assert log.counts["no_pose"] == 2 and log.scans.num_scans == 2
    assert np.array_equal(log.message_indices, [0, 1])
    short = 2 * np.pi - 6.0  # from 3.0 to -3.0 through pi
    np.testing.assert_allclose(log.scans.poses[0], [0.5, -1.0, 3.0 + 0.5 * short], rtol=0, atol=1e-12)
    np.testing.assert_allclose(log.scans.poses[1, :2], [1.0, -2.0], rtol=0, atol=0)
    assert abs(_wrap(log.scans.poses[1, 2] + 3.0)) < 1e-12
    wide = read_bag(p, "/scan", "/pose", pose_tolerance=3.0)
    assert wide.counts["no_pose"] == 1
    np.testing.assert_allclose(wide.scans.poses[2, :2], [1.0 + 2.0 * 2.5 / 4.5, -2.0 + 2.0 * 2.5 / 4.5], atol=1e-12)
    with pytest.raises(BagFormatError, match=r"none of the 1 scans has a pose within 0\.0 s"):
        read_bag(
            _write(tmp_path / "j.bag", "ros1", [_pose(0, 0, 0, 0), _scan(S // 4), _pose(S, 0, 0, 0)]),
            "/scan",
            "/pose",
            pose_tolerance=0.0,
        )


def test_tf_links_are_interpolated_and_composed(tmp_path):
    """A dynamic map -> base_link link sampled at 0 s and 1 s and a static base_link -> laser mounting:
    the scan at 0.5 s is the slerp / lerp midpoint composed with the mounting."""
    msgs = [
        ("/tf_static", TF_MESSAGE, 0, {"tf": [("base_link", "laser", 0.5, 0.0, np.pi / 2)]}),
        ("/tf", TF_MESSAGE, 0, {"tf": [("map", "base_link", 0.0, 0.0, 0.0)]}),
        _scan(S // 2),
        ("/tf", TF_MESSAGE, S, {"tf": [("/map", "/base_link", 2.0, 0.0, np.pi / 2)]}),
    ]
    p = _write(tmp_path / "tf", "sqlite3", msgs)
    pose = read_bag(p, "/scan", tf=True, pose_tolerance=1.0).scans.poses[0]
    a = np.pi / 4  # base_link at (1, 0, pi/4); laser 0.5 m ahead of it, turned by pi/2
    np.testing.assert_allclose(pose, [1.0 + 0.5 * math.cos(a), 0.5 * math.sin(a), a + np.pi / 2], atol=1e-12)
    with pytest.raises(BagFormatError, match="no transform chain from 'odom' to the laser frame 'laser'"):
        read_bag(p, "/scan", tf=True, map_frame="odom")


def test_an_upside_down_laser_turns_its_beams_the_other_way(tmp_path):
    """A laser mounted upside down (roll pi) and turned by yaw 0.3: its beam at +0.5 rad points to
    0.3 - 0.5 in the map; the scan's yaw is the heading of the laser's x axis."""
    msgs = [
        ("/tf_static", TF_MESSAGE, 0, {"tf": [("base_link", "laser", 0.0, 0.0, 0.3, np.pi)]}),
        ("/tf", TF_MESSAGE, 0, {"tf": [("map", "base_link", 1.0, 2.0, 0.0)]}),
        _scan(S // 2, (1.0, 2.0), angle_min=-0.5, angle_increment=1.0),
        ("/tf", TF_MESSAGE, S, {"tf": [("map", "base_link", 1.0, 2.0, 0.0)]}),
    ]
    s = read_bag(_write(tmp_path / "flip.bag", "ros1", msgs), "/scan", tf=True, pose_tolerance=1.0).scans
    np.testing.assert_allclose(s.poses[0], [1.0, 2.0, 0.3], atol=1e-12)
    np.testing.assert_allclose(s.world_angles()[0], [0.3 + 0.5, 0.3 - 0.5], atol=1e-12)


def test_angles_of_the_laser_geometry_are_recovered():
    for p, q in ((-1, 2), (1, 180), (1, 720), (1, 512), (-3, 4), (2, 3)):
        exact = p * math.pi / q
        assert _angle64(float(np.float32(exact)), "decimal") == exact
    assert _angle64(float(np.float32(0.123456)), "decimal") == 0.123456  # not a fraction of pi: its decimal
    assert _angle64(float(np.float32(0.1)), "binary") == float(np.float32(0.1))


def test_ranges_widen_to_the_shortest_decimal_of_their_float32():
    """The vectorised widening equals numpy's shortest repr of every float32 (all bit patterns drawn at
    random, sentinels and decimals), and "binary" keeps the float32 value."""
    rng = np.random.default_rng(2)
    a = np.concatenate(
        [
            rng.integers(0, 2**32, 200_000, dtype=np.uint64).astype(np.uint32).view(np.float32),
            np.round(rng.uniform(0, 90, 50_000), 2).astype(np.float32),
            np.array([0.0, -0.0, np.inf, -np.inf, np.nan, 81.83, 1e-40, 3e38], dtype=np.float32),
        ]
    ).reshape(-1, 2)
    with np.errstate(all="ignore"):
        ref, binary = a.astype(str).astype(np.float64), a.astype(np.float64)
    got = _widen_array(a, "decimal")
    assert got.shape == a.shape and np.array_equal(got, ref, equal_nan=True)
    assert np.array_equal(_widen_array(a, "binary"), binary, equal_nan=True)


# ------------------------------------------------------------------------- errors
def _errs(tmp_path, storage="ros1"):
    """One scan of each malformed kind between good ones, and a pose with a zero quaternion."""
    msgs = [
        _pose(0, 0, 0, 0),
        _scan(S // 10),
        _scan(2 * S // 10, angle_increment=0.0),
        _scan(3 * S // 10, range_min=5.0, range_max=2.0),
        _scan(4 * S // 10, ranges=(1.0, -2.0)),
        _scan(5 * S // 10, angle_max=3.0),
        _scan(6 * S // 10, ranges=()),
        _pose(7 * S // 10, 0, 0, 0, qnorm=0.0),
        _scan(8 * S // 10),
        _pose(S, 1.0, 0, 0),
    ]
    return _write(_bag_path(tmp_path, storage, "errs"), storage, msgs)


@pytest.mark.parametrize("storage", STORAGES)
def test_strict_names_file_topic_index_and_field_lenient_keeps_the_rest(tmp_path, storage):
    p = _errs(tmp_path, storage)
    with pytest.raises(BagFormatError) as e:
        read_bag(p, "/scan", "/pose", pose_tolerance=1.0)
    assert str(e.value).startswith(f"{p}, topic /scan, message 1, field 'angle_increment': is 0 for 2 beams")
    log = read_bag(p, "/scan", "/pose", strict=False, pose_tolerance=1.0)
    assert log.scans.num_scans == 2 and np.array_equal(log.message_indices, [0, 6])
    fields = [(t, i, r.split(":")[0]) for t, i, r in log.bad_messages]
    assert fields == [
        ("/scan", 1, "field 'angle_increment'"),
        ("/scan", 2, "field 'range_min'"),
        ("/scan", 3, "field 'ranges[1]'"),
        ("/scan", 4, "field 'angle_max'"),
        ("/scan", 5, "field 'ranges'"),
        ("/pose", 1, "field 'pose.orientation'"),
    ]


def test_bad_arguments_and_files(tmp_path, bags):
    p = bags["ros1"]
    with pytest.raises(BagFormatError, match=r"no scan topic '/laser' in the bag; its topics: /odom \(nav_msgs"):
        read_bag(p, "/laser", "/odom")
    with pytest.raises(BagFormatError, match="pose topic '/scan' holds sensor_msgs/msg/LaserScan, expected"):
        read_bag(p, "/scan", "/scan")
    with pytest.raises(BagFormatError, match="tf=True but the bag has no /tf"):
        read_bag(p, "/scan", tf=True)
    with pytest.raises(ValueError, match="give pose_topic or tf=True"):
        read_bag(p, "/scan", "/odom", tf=True)
    with pytest.raises(ValueError, match="max_usable_range must be a finite number > 0"):
        read_bag(p, "/scan", "/odom", max_usable_range=float("nan"))
    with pytest.raises(BagFormatError, match="no such file"):
        read_bag(tmp_path / "none.bag", "/scan", "/odom")
    (tmp_path / "x.bag").write_text("FLASER 1 1.0 0 0 0 0 0 0 1 h 1\n")
    with pytest.raises(BagFormatError, match="not a ROS bag"):
        read_bag(tmp_path / "x.bag", "/scan", "/odom")
    (tmp_path / "y.log").write_bytes(p.read_bytes())
    with pytest.raises(BagFormatError, match=r"suffix \.bag"):
        read_bag(tmp_path / "y.log", "/scan", "/odom")
    assert bag_kind(p) == "ros1" and bag_kind(bags["mcap"]) == "mcap" and bag_kind(bags["sqlite3"]) == "sqlite3"
    assert bag_kind(tmp_path / "x.bag") is None and bag_kind(tmp_path) is None


@needs_data
@pytest.mark.parametrize("storage", ["ros1", "mcap"])
def test_a_bag_cut_short_keeps_every_scan_before_the_cut(bags, tmp_path, storage):
    """No index (ROS 1) or summary (MCAP) at the end, as a recording cut short leaves it (``.bag.active``):
    strict mode refuses it and says why; lenient mode reads it record by record and keeps every message
    before the cut."""
    import shutil

    src = bags[storage]
    full = read_bag(src, "/scan", "/odom")
    data_file = src if storage == "ros1" else next(src.glob("*.mcap"))
    data = data_file.read_bytes()
    for frac, name in ((0.5, "cut.bag"), (0.9, "cut.bag.active")):
        p = tmp_path / (name if storage == "ros1" else f"{name}_{storage}")
        if storage == "ros1":
            p.write_bytes(data[: int(len(data) * frac)])
        else:
            shutil.copytree(src, p)
            (p / data_file.name).write_bytes(data[: int(len(data) * frac)])
        with pytest.raises(BagFormatError, match="strict=False / --lenient reads it record by record"):
            read_bag(p, "/scan", "/odom")
        log = read_bag(p, "/scan", "/odom", strict=False)
        n = log.scans.num_scans
        assert 0.4 * frac * 40 < n < 40
        _assert_same_scans(log.scans, _slice(full.scans, slice(0, n)), yaw_tol=0.0)
        ((topic, index, note),) = log.bad_messages
        assert (topic, index) == ("", -1) and note.startswith("no usable "), note
        assert "read record by record; reading stopped" in note


@needs_data
@pytest.mark.parametrize("storage", STORAGES)
def test_fuzz_truncated_and_corrupted_bags(bags, tmp_path, storage):
    """Cut files and flipped bytes: a clear BagFormatError naming the file, or scans read (lenient mode
    says where it stopped or what it skipped); never another exception, never slow."""
    import shutil

    rng = np.random.default_rng(1)
    src = bags[storage]
    data_file = src if src.is_file() else next(f for f in src.iterdir() if f.suffix in (".db3", ".mcap"))
    data = data_file.read_bytes()
    outcomes = []
    for trial in range(10):
        q = tmp_path / (f"c{trial}.bag" if src.is_file() else f"c{trial}")
        if src.is_dir():
            shutil.copytree(src, q)
        target = q if src.is_file() else q / data_file.name
        b = bytearray(data)
        if trial < 3:
            b = b[: int(len(b) * (0.3 + 0.3 * trial))]
        else:
            for _ in range(2 * trial):
                b[int(rng.integers(len(b)))] = int(rng.integers(256))
        target.write_bytes(bytes(b))
        for strict in (True, False):
            t0 = time.perf_counter()
            try:
                log = read_bag(q, "/scan", "/odom", strict=strict)
                outcomes.append("read")
                assert log.scans.num_scans + len(log.bad_messages) >= 1
            except BagFormatError as e:
                outcomes.append("error")
                assert str(e).startswith(str(q))
            assert time.perf_counter() - t0 < 10.0
    assert "error" in outcomes  # the cut files at least


@needs_data
@pytest.mark.parametrize("storage", STORAGES)
def test_write_bag_replaces_its_own_bag_and_refuses_other_things(intel, tmp_path, storage):
    """A second write to the same path replaces the bag (the docs' example reruns), leaving no staging
    files; a folder that is no ROS 2 bag (or a folder where a ROS 1 bag file goes) is refused, untouched."""
    scans, stamps = intel
    p = _bag_path(tmp_path, storage)
    write_bag(p, _slice(scans, slice(0, 10)), stamps[:10], storage=storage)
    assert write_bag(p, scans, stamps, storage=storage) == p
    assert read_bag(p, "/scan", "/odom").scans.num_scans == scans.num_scans
    assert sorted(x.name for x in tmp_path.iterdir()) == [p.name]
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "notes.txt").write_text("keep")
    with pytest.raises(ValueError, match=r"not replacing it|is a folder"):
        write_bag(mine, scans, stamps, storage=storage)
    assert (mine / "notes.txt").read_text() == "keep" and len(list(tmp_path.iterdir())) == 2
