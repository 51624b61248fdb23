"""CARMEN log reader: the shared real logs, hand-written logs for every rule, strict errors, fuzzing."""

import gzip
import math
import re
import time
import warnings
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ogm_ppl.datasets import CarmenFormatError, read_carmen
from ogm_ppl.datasets.carmen import CarmenReadWarning, flaser_angles

DATA = Path(__file__).resolve().parents[3] / "shared" / "data"  # shared/ beside the repository
INTEL = DATA / "intel-lab" / "intel-corrected.log.gz"
# file: (FLASER scans, beams, ODOM lines, no-return threshold) from carmen/PROVENANCE.md
REAL = {
    "csail": (406, 361, 2394, 81.83),
    "freiburg-101": (292, 360, 4569, 81.83),
    "seattle": (241, 361, 19311, 81.83),
    "infinite-corridor": (1941, 180, 18191, 50.5),
    "freiburg-campus": (2008, 360, 17691, 81.83),
    "fhw": (488, 180, 13935, 50.5),
    "belgioioso": (395, 361, 4442, 81.83),
    "edmonton": (340, 180, 6351, 50.5),
    "acapulco": (861, 181, 12142, 50.5),
}
needs_data = pytest.mark.skipif(not INTEL.exists(), reason="shared data not present")


def flaser(ranges, pose=(0.0, 0.0, 0.0), ts=1.0, n=None):
    n = len(ranges) if n is None else n
    r = " ".join(repr(float(v)) for v in ranges)
    p = " ".join(repr(float(v)) for v in pose)
    return f"FLASER {n} {r} {p} {p} {ts!r} host {ts!r}"


def robotlaser(ranges, start=-1.5, res=0.01, max_range=50.0, pose=(0.0, 0.0, 0.0), rem=(), ts=1.0):
    r = " ".join(repr(float(v)) for v in ranges)
    e = " ".join([str(len(rem)), *(repr(float(v)) for v in rem)])
    p = " ".join(repr(float(v)) for v in pose)
    head = f"ROBOTLASER1 0 {start!r} 3.14 {res!r} {max_range!r} 0.01 0"
    return f"{head} {len(ranges)} {r} {e} {p} 9 9 9 0.1 0.2 0.5 0.3 0.0 {ts!r} host {ts!r}"


def write(tmp_path, lines, name="t.log", gz=False):
    data = ("\n".join(lines) + "\n").encode("latin-1")
    path = tmp_path / name
    path.write_bytes(gzip.compress(data) if gz else data)
    return path


# ------------------------------------------------------------------------------- real logs
@needs_data
def test_intel_log_counts_sentinel_and_speed():
    read_carmen(INTEL)  # warm caches
    t = time.process_time()
    log = read_carmen(INTEL)
    assert time.process_time() - t < 1.0
    s = log.scans
    assert (s.num_scans, s.beams_per_scan) == (910, 180)
    assert log.num_lines == 16365 and log.skipped_types == {"ODOM": 14541, "NEFF": 910}
    assert log.counts["no_return"] == 4172 and s.num_valid == 163800 - 4172  # 81.83 m: 2.55 %
    assert log.max_range == 81.83 and not s.is_max.any()
    assert s.poses[:, 0].min() == pytest.approx(-9.2, abs=0.1)
    assert s.poses[:, 1].max() == pytest.approx(3.9, abs=0.1)
    assert np.all(np.diff(log.line_numbers) > 0)
    xmin, xmax, ymin, ymax = log.extent()
    assert xmin < -9.2 and xmax > 16.5 and ymin < -22.1 and ymax > 3.9
    grid = log.grid(0.1)
    assert grid.contains(s.poses[:, :2]).all()


@needs_data
def test_intel_twenty_metre_rule_of_section_6_2():
    drop = read_carmen(INTEL, max_usable_range=20.0)
    clip = read_carmen(INTEL, max_usable_range=20.0, usable_range_rule="max")
    assert drop.counts["beyond_usable"] == clip.counts["beyond_usable"] == 269
    assert drop.max_range == clip.max_range == 20.0
    assert drop.scans.num_valid == 163800 - 4172 - 269 and not drop.scans.is_max.any()
    assert clip.scans.num_valid == 163800 - 4172 and clip.scans.is_max.sum() == 269
    half = read_carmen(INTEL, max_usable_range=20.0, pose_fraction=0.1, beam_step=2)
    assert (half.scans.num_scans, half.scans.beams_per_scan) == (91, 90)


@needs_data
@pytest.mark.parametrize("name", sorted(REAL))
def test_every_shared_carmen_log(name):
    scans_n, beams, odom, threshold = REAL[name]
    log = read_carmen(DATA / "carmen" / f"{name}-corrected.log.gz")
    s = log.scans
    assert (s.num_scans, s.beams_per_scan) == (scans_n, beams)
    assert log.skipped_types["ODOM"] == odom and log.skipped_types["NEFF"] == scans_n
    assert log.bad_lines == [] and log.settings["auto_no_return_threshold"] == threshold
    dropped = 1 - s.num_valid / s.num_readings
    assert 0.001 < dropped < 0.3  # sentinels: 0.5 % (Belgioioso) .. 26 % (Freiburg campus)
    assert np.all(s.ranges[s.valid] < threshold) and np.all(np.isfinite(s.poses))
    step = np.diff(s.angles[0])
    assert np.allclose(step, math.pi / (beams - 1 if beams % 2 else beams))
    assert s.angles[0, 0] == pytest.approx(-math.pi / 2)


# ------------------------------------------------------------------------ hand-written logs
def test_flaser_values_angles_and_plain_vs_gzip(tmp_path):
    lines = [
        "# comment",
        "ODOM 0 0 0 0 0 0 1 host 1",
        flaser([1.0, 2.0, 3.0], (1.0, 2.0, 0.5), ts=7.0),
    ]
    plain = read_carmen(write(tmp_path, lines))
    zipped = read_carmen(write(tmp_path, lines, name="t.txt", gz=True))  # magic bytes, not the name
    for log in (plain, zipped):
        assert log.scans.ranges.tolist() == [[1.0, 2.0, 3.0]]
        assert log.scans.poses.tolist() == [[1.0, 2.0, 0.5]]
        assert np.allclose(log.scans.angles[0], [-math.pi / 2, 0.0, math.pi / 2])
        assert log.line_numbers.tolist() == [3] and log.timestamps.tolist() == [7.0]
        assert log.skipped_types == {"ODOM": 1} and log.num_lines == 3


def test_flaser_angle_rule_odd_and_even():
    assert np.allclose(np.degrees(flaser_angles(180)), np.arange(-90, 90))
    assert np.allclose(np.degrees(flaser_angles(181)), np.arange(-90, 91))
    assert np.allclose(np.degrees(flaser_angles(360)), np.arange(-90, 90, 0.5))
    assert np.allclose(np.degrees(flaser_angles(361)), np.arange(-90, 90.5, 0.5))


def test_param_fov_resolution_and_offset(tmp_path):
    fov = ["PARAM laser_front_laser_fov 1.5 0 host 0", flaser([1.0, 1.0, 1.0])]
    assert np.allclose(read_carmen(write(tmp_path, fov)).scans.angles[0], [-0.75, 0.0, 0.75])
    deg = ["PARAM laser_front_laser_fov 90 0 host 0", flaser([1.0, 1.0])]  # degrees, even n
    assert np.allclose(np.degrees(read_carmen(write(tmp_path, deg)).scans.angles[0]), [-45, 0])
    res = ["PARAM laser_frontlaser_resolution 2 0.0 nohost 0", flaser([1.0] * 4)]  # FHW spelling
    assert np.allclose(np.degrees(read_carmen(write(tmp_path, res)).scans.angles[0]), [-4, -2, 0, 2])
    off = ["PARAM robot_frontlaser_offset 0.5 nohost 0", flaser([1.0], (1.0, 1.0, math.pi / 2))]
    log = read_carmen(write(tmp_path, off))
    assert log.settings["frontlaser_offset"] == 0.5 and log.scans.poses.tolist() == [[1.0, 1.0, math.pi / 2]]
    moved = read_carmen(write(tmp_path, off), apply_laser_offset=True)
    assert np.allclose(moved.scans.poses, [[1.0, 1.5, math.pi / 2]])
    rear = ["RLASER 1 2.0 0 0 0 0 0 0 1 host 1", flaser([1.0])]
    assert read_carmen(write(tmp_path, rear)).skipped_types == {"RLASER": 1}


def test_robotlaser1_geometry_max_range_and_auto_choice(tmp_path):
    lines = [
        flaser([1.0, 2.0]),
        robotlaser([1.0, 9.0, 2.0], start=-0.2, res=0.1, max_range=8.0, pose=(3.0, 4.0, 0.1), rem=(5.0, 6.0)),
    ]
    log = read_carmen(write(tmp_path, lines))  # auto: ROBOTLASER1 only, FLASER counted as skipped
    assert log.skipped_types == {"FLASER": 1} and log.line_numbers.tolist() == [2]
    assert np.allclose(log.scans.angles, [[-0.2, -0.1, 0.0]]) and log.scans.poses.tolist() == [[3.0, 4.0, 0.1]]
    assert log.scans.valid.tolist() == [[True, False, True]] and log.max_range == 8.0
    as_max = read_carmen(write(tmp_path, lines), no_return="max")
    assert as_max.scans.is_max.tolist() == [[False, True, False]] and as_max.scans.ranges[0, 1] == 8.0
    both = read_carmen(write(tmp_path, lines), messages=("FLASER", "ROBOTLASER1"))
    s = both.scans
    assert s.ranges.shape == (2, 3) and s.valid.tolist() == [
        [True, True, False],
        [True, False, True],
    ]
    assert np.allclose(s.angles[0, :2], [-math.pi / 2, 0.0])


def test_sentinels_dropped_or_max_and_threshold(tmp_path):
    lines = [flaser([1.0, 81.83, 81.91, 40.0]), flaser([2.0, 3.0, 81.91, 0.1])]
    drop = read_carmen(write(tmp_path, lines))
    assert drop.scans.valid.tolist() == [[True, False, False, True], [True, True, False, True]]
    assert drop.counts["no_return"] == 3 and drop.max_range == 81.83
    mx = read_carmen(write(tmp_path, lines), no_return="max")
    assert mx.scans.is_max.sum() == 3 and mx.scans.num_valid == 8
    thr = read_carmen(write(tmp_path, lines), no_return_threshold=30.0, min_range=0.5)
    assert thr.scans.valid.tolist() == [[True, False, False, False], [True, True, False, False]]
    assert thr.counts["below_min"] == 1
    band51 = read_carmen(write(tmp_path, [flaser([1.0, 51.15, 50.1])]))
    assert band51.scans.valid.tolist() == [[True, False, True]]
    none = read_carmen(write(tmp_path, [flaser([1.0, 45.0])]))  # no sentinel: nothing dropped
    assert none.scans.num_valid == 2 and not none.scans.is_max.any() and none.max_range > 45.0
    given = read_carmen(write(tmp_path, [flaser([1.0, 45.0])]), max_range=30.0)
    assert given.scans.is_max.tolist() == [[False, True]]


def test_usable_range_rule(tmp_path):
    path = write(tmp_path, [flaser([5.0, 20.0, 25.0, 81.83])])
    drop = read_carmen(path, max_usable_range=20.0)
    assert drop.scans.valid.tolist() == [[True, False, False, False]]
    clip = read_carmen(path, max_usable_range=20.0, usable_range_rule="max")
    assert clip.scans.is_max.tolist() == [[False, True, True, False]] and clip.scans.ranges[0, 2] == 20.0


def test_subsampling(tmp_path):
    lines = [flaser([float(i + 1)] * 4, ts=float(i)) for i in range(10)]
    path = write(tmp_path, lines)
    assert read_carmen(path, pose_step=3).line_numbers.tolist() == [1, 4, 7, 10]
    frac = read_carmen(path, pose_fraction=0.5)
    assert frac.line_numbers.tolist() == [1, 3, 5, 7, 9]
    assert frac.scans.ranges[:, 0].tolist() == [1.0, 3.0, 5.0, 7.0, 9.0]
    half = read_carmen(path, beam_step=2, pose_fraction=0.1)
    assert half.scans.ranges.shape == (1, 2) and np.allclose(half.scans.angles, [[-math.pi / 2, 0.0]])
    assert half.counts["beams"] == 2
    with pytest.raises(ValueError):
        read_carmen(path, pose_step=2, pose_fraction=0.5)


# --------------------------------------------------------------------------- strict / lenient
@pytest.mark.parametrize(
    ("bad", "field"),
    [
        (flaser([1.0, 2.0]).replace(" 2.0 ", " abc ", 1), "range[1]"),
        (flaser([1.0, 2.0]).replace(" 2.0 ", " nan ", 1), "range[1]"),
        (flaser([1.0, 2.0]).replace(" 2.0 ", " -2.0 ", 1), "range[1]"),
        (flaser([1.0, 2.0], n=3), "line length"),
        ("FLASER two 1.0", "num_readings"),
        (flaser([1.0], pose=(float("inf"), 0.0, 0.0)), "x"),
        (flaser([1.0], pose=(0.0, 0.0, 0.0)).replace(" 1.0 host", " x host"), "ipc_timestamp"),
        ("PARAM laser_front_laser_fov wide 0 host 0", "PARAM laser_front_laser_fov"),
        ("PARAM robot_frontlaser_offset", "value"),
        (robotlaser([1.0], res=float("nan")), "angular_res"),
        ("\x00\x01garbage", "message type"),
    ],
)
def test_strict_error_names_file_line_and_field(tmp_path, bad, field):
    path = write(tmp_path, [flaser([1.0, 2.0]), "ODOM 0 0 0 0 0 0 1 host 1", bad, flaser([3.0, 4.0])])
    with pytest.raises(CarmenFormatError) as e:
        read_carmen(path, messages=("FLASER", "ROBOTLASER1"))
    assert (e.value.line_no, e.value.field) == (3, field)
    assert str(path) in str(e.value) and "line 3" in str(e.value) and repr(field) in str(e.value)
    assert "np." not in str(e.value)  # values as written (nan), not numpy's repr (np.float64(nan))
    log = read_carmen(path, strict=False, messages=("FLASER", "ROBOTLASER1"))
    assert [no for no, _ in log.bad_lines] == [3] and field in log.bad_lines[0][1]
    assert log.line_numbers.tolist() == [1, 4] and log.scans.ranges[:, :2].tolist() == [
        [1.0, 2.0],
        [3.0, 4.0],
    ]


def test_empty_truncated_gzip_and_no_scans(tmp_path):
    with pytest.raises(CarmenFormatError, match="no readable laser scans"):
        read_carmen(write(tmp_path, ["ODOM 0 0 0 0 0 0 1 host 1"]))
    empty = tmp_path / "empty.log"
    empty.write_bytes(b"")
    with pytest.raises(CarmenFormatError, match="line 0"):
        read_carmen(empty)
    data = gzip.compress(("\n".join(flaser([float(i)] * 50) for i in range(1, 200)) + "\n").encode())
    cut = tmp_path / "cut.log.gz"
    cut.write_bytes(data[: len(data) // 2])
    with pytest.raises(CarmenFormatError, match="gzip") as e:
        read_carmen(cut)
    with pytest.warns(CarmenReadWarning, match="stopped at line"):
        log = read_carmen(cut, strict=False)
    assert log.bad_lines[0][0] == log.scans.num_scans + 1 and 0 < log.scans.num_scans < 199
    assert f"line {log.scans.num_scans + 1}," in str(e.value)  # strict mode names the line it stops at too
    assert log.scans.ranges[:, 0].tolist() == list(range(1, log.scans.num_scans + 1))


def test_lenient_gzip_with_a_flipped_byte_keeps_the_lines_before_it(tmp_path):
    """One flipped byte in the middle of the deflate data: strict mode names the gzip stream; lenient mode
    keeps the scans before the damage (at least those in the first third of the stream) and warns with the
    line at which it stopped."""
    n = 400
    text = "\n".join(flaser([float(i % 97 + 1)] * 40, ts=float(i)) for i in range(n)) + "\n"
    data = bytearray(gzip.compress(text.encode(), compresslevel=6))
    data[len(data) // 2] ^= 0xFF
    path = tmp_path / "flip.log.gz"
    path.write_bytes(bytes(data))
    with pytest.raises(CarmenFormatError, match="gzip"):
        read_carmen(path)
    with pytest.warns(CarmenReadWarning, match=r"flip\.log\.gz.*stopped at line (\d+)") as rec:
        log = read_carmen(path, strict=False)
    stop = int(re.search(r"stopped at line (\d+)", str(rec[0].message)).group(1))
    assert n // 3 < log.scans.num_scans < n
    assert stop > log.scans.num_scans  # every line before the stop line is read (bad ones are listed)
    good = log.scans.ranges[:, 0]
    assert good[: n // 3].tolist() == [float(i % 97 + 1) for i in range(n // 3)]


@pytest.mark.parametrize(
    "option, value, exc",
    [
        ("no_return_threshold", float("nan"), ValueError),
        ("max_usable_range", -5.0, ValueError),
        ("max_usable_range", "20", TypeError),
        ("max_range", float("inf"), ValueError),
        ("min_range", -1.0, ValueError),
    ],
)
def test_bad_numeric_options_name_the_option(tmp_path, option, value, exc):
    path = write(tmp_path, [flaser([1.0, 81.83, 2.0])])
    with pytest.raises(exc, match=f"read_carmen: {option}"):
        read_carmen(path, **{option: value})


# ------------------------------------------------------------------------------------ fuzzing
finite = st.floats(0.1, 30.0).map(lambda v: round(v, 3))
pose = st.tuples(st.floats(-50, 50), st.floats(-50, 50), st.floats(-3.2, 3.2)).map(
    lambda p: tuple(round(v, 4) for v in p)
)
good_line = st.one_of(
    st.builds(lambda r, p: ("F", r, p), st.lists(finite, min_size=1, max_size=6), pose),
    st.builds(lambda r, p: ("R", r, p), st.lists(finite, min_size=1, max_size=6), pose),
)
GARBAGE = ["nan", "inf", "-inf", "abc", "1,5", "--", "", "0x1p3", "1e400"]


def render(item):
    kind, r, p = item
    return flaser(r, p) if kind == "F" else robotlaser(r, pose=p, rem=r[:2])


@st.composite
def broken(draw, line):
    """A mutation of a good line that is guaranteed not to be a good line."""
    t = line.split()
    n = len(t)
    how = draw(st.sampled_from(["truncate", "delete", "garbage", "count"]))
    if how == "truncate":
        return " ".join(t[: draw(st.integers(1, n - 1))])
    if how == "delete":
        i = draw(st.integers(1, n - 1))
        return " ".join(t[:i] + t[i + 1 :])
    if how == "count":
        i = 1 if t[0] == "FLASER" else 8
        return " ".join(t[:i] + [str(int(t[i]) + draw(st.sampled_from([-1, 1, 7])))] + t[i + 1 :])
    # a range or the x y theta pose: tokens the reader validates
    nr = int(t[1]) if t[0] == "FLASER" else int(t[8])
    first = 2 if t[0] == "FLASER" else 9
    pose_at = first + nr if t[0] == "FLASER" else first + nr + 1 + int(t[first + nr])
    i = draw(st.sampled_from([*range(first, first + nr), pose_at, pose_at + 1, pose_at + 2]))
    g = draw(st.sampled_from(GARBAGE if i >= pose_at else [*GARBAGE, "-1.0"]))
    return " ".join(t[:i] + ([g] if g else []) + t[i + 1 :])


# a line of noise never starts with the gzip magic: a file whose first bytes are 1f 8b is read as gzip (the reader
# tells plain from gzip by magic bytes), and a noise line may come first
noise = st.one_of(
    st.binary(max_size=60).map(lambda b: b.replace(b"\n", b" ").decode("latin-1")),
    st.text(alphabet="FLASER0123456789 .-enaib#", max_size=40),
).filter(lambda line: not line.startswith("\x1f\x8b"))


@settings(max_examples=60, deadline=None)
@given(data=st.data(), items=st.lists(good_line, min_size=1, max_size=5))
def test_lenient_keeps_every_good_line_exactly(tmp_path_factory, data, items):
    lines, expected = [], []
    for item in items:
        for _ in range(data.draw(st.integers(0, 2))):
            lines.append(data.draw(st.one_of(broken(render(data.draw(good_line))), noise)))
        lines.append(render(item))
        expected.append((len(lines), item))
    gz = data.draw(st.booleans())
    path = write(tmp_path_factory.mktemp("fz"), lines, gz=gz)
    log = read_carmen(path, strict=False, messages=("FLASER", "ROBOTLASER1"))
    assert log.line_numbers.tolist() == [no for no, _ in expected]
    for s, (_, (_, r, p)) in enumerate(expected):
        assert log.scans.ranges[s, : len(r)].tolist() == r and log.scans.valid[s, : len(r)].all()
        assert not log.scans.valid[s, len(r) :].any()
        assert log.scans.poses[s].tolist() == list(p)
    bad_nos = {no for no, _ in log.bad_lines}
    assert not bad_nos & {no for no, _ in expected}


@settings(max_examples=80, deadline=None)
@given(data=st.data(), items=st.lists(good_line, min_size=1, max_size=3))
def test_strict_raises_only_carmen_format_error(tmp_path_factory, data, items):
    lines = [render(i) for i in items]
    target = data.draw(st.integers(0, len(lines) - 1))
    line = lines[target]
    how = data.draw(st.sampled_from(["broken", "chars", "shuffle", "noise"]))
    if how == "broken":
        lines[target] = data.draw(broken(line))
    elif how == "chars":  # cut anywhere, possibly inside a token
        lines[target] = line[: data.draw(st.integers(0, len(line)))]
    elif how == "shuffle":
        t = line.split()
        lines[target] = " ".join([t[0], *data.draw(st.permutations(t[1:]))])
    else:
        lines.insert(target, data.draw(noise))
    path = write(tmp_path_factory.mktemp("fz"), lines, gz=data.draw(st.booleans()))
    try:
        log = read_carmen(path, messages=("FLASER", "ROBOTLASER1"))
    except CarmenFormatError as e:
        assert str(path) in str(e)
        if how == "broken":
            assert e.line_no == target + 1
    else:
        assert how != "broken" and np.all(np.isfinite(log.scans.poses))


@settings(max_examples=40, deadline=None)
@given(raw=st.binary(max_size=400), gz=st.booleans())
def test_random_bytes_raise_only_carmen_format_error(tmp_path_factory, raw, gz):
    path = tmp_path_factory.mktemp("fz") / "r.log"
    path.write_bytes(gzip.compress(raw) if gz else raw)
    for strict in (True, False):
        try:
            read_carmen(path, strict=strict)
        except CarmenFormatError:
            pass


def test_subsampling_matches_scans_subsample(tmp_path):
    lines = [flaser([float(i % 7 + 1)] * 6, pose=(i, 0.0, 0.0)) for i in range(23)]
    path = write(tmp_path, lines)
    full = read_carmen(path).scans
    for kw in ({"pose_fraction": 0.3}, {"pose_fraction": 0.1, "beam_step": 2}, {"pose_step": 4}):
        mine, theirs = read_carmen(path, **kw).scans, full.subsample(**kw)
        for name in ("poses", "angles", "ranges", "valid"):
            assert np.array_equal(getattr(mine, name), getattr(theirs, name)), (kw, name)
    for kw in ({"pose_step": 0}, {"beam_step": 0}, {"pose_fraction": 0.0}, {"no_return": "keep"}):
        with pytest.raises(ValueError):
            read_carmen(path, **kw)


def test_laser_type_not_read_is_not_checked(tmp_path):
    path = write(tmp_path, ["FLASER 3 1.0", robotlaser([1.0, 2.0])])
    log = read_carmen(path)  # auto: ROBOTLASER1; the broken FLASER line is skipped, not an error
    assert log.skipped_types == {"FLASER": 1} and log.bad_lines == []
    with pytest.raises(CarmenFormatError, match="line 1"):
        read_carmen(path, messages="FLASER")


def test_log_round_trips_through_a_dataset_file(tmp_path):
    from ogm_ppl.datasets import load_dataset, save_dataset

    lines = [
        "PARAM laser_front_laser_fov 3.14159 0 host 0",
        flaser([1.0, 81.91, 3.0], (1.0, 2.0, 0.5)),
    ]
    log = read_carmen(write(tmp_path, lines), max_usable_range=2.5, usable_range_rule="max")
    d = load_dataset(save_dataset(tmp_path / "d.npz", log.scans, grid=log.grid(0.5), settings=log.settings))
    assert d.settings == log.settings and d.grid == log.grid(0.5)
    assert np.array_equal(d.scans.ranges, log.scans.ranges) and np.array_equal(d.scans.is_max, log.scans.is_max)
    assert d.scans.valid.tolist() == [[True, False, True]] and d.scans.is_max.tolist() == [[False, False, True]]


def test_a_pose_far_from_the_one_before_it_is_named(tmp_path):
    """Consecutive scans 1 km apart (a mistyped pose) warn with the lines; 1.8 m steps, as in the corrected
    logs, do not."""
    steps = [flaser([1.0, 2.0], pose=(1.8 * i, 0.0, 0.0)) for i in range(4)]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        read_carmen(write(tmp_path, steps))
    jump = [*steps[:2], flaser([1.0, 2.0], pose=(1000.0, 0.0, 0.0)), *steps[2:]]
    with pytest.warns(CarmenReadWarning, match=r"moves 998\.2 m between lines 2 and 3 \(2 steps over 25 m\)"):
        log = read_carmen(write(tmp_path, jump))
    assert log.scans.num_scans == 5  # read all the same
