import numpy as np
import pytest

from ogm_ppl import Scans


def make(**kw):
    args = dict(poses=[[0.0, 0.0, 0.0], [1.0, 1.0, 0.5]], angles=[0.0, 0.1, 0.2], ranges=np.ones((2, 3)), max_range=5.0)
    args.update(kw)
    return Scans(**args)


def test_shapes_and_max_flags():
    s = make(ranges=[[1.0, 5.0, 2.0], [0.0, 4.9, 5.0]])
    assert s.num_scans == 2 and s.beams_per_scan == 3 and s.num_readings == 6
    np.testing.assert_array_equal(s.is_max, [[False, True, False], [False, False, True]])
    assert s.angles.shape == (2, 3)
    np.testing.assert_allclose(s.world_angles()[1], [0.5, 0.6, 0.7])


@pytest.mark.parametrize(
    "ranges, message",
    [
        ([[1.0, np.nan, 1.0], [1.0, 1.0, 1.0]], r"ranges is NaN at index \(0, 1\)"),
        ([[1.0, 1.0, 1.0], [1.0, np.inf, 1.0]], r"ranges is infinite at index \(1, 1\)"),
        ([[1.0, 1.0, 1.0], [1.0, 1.0, -0.5]], r"ranges is negative \(-0.5\) at index \(1, 2\)"),
        ([[1.0, 7.0, 1.0], [1.0, 1.0, 1.0]], r"exceeds max_range = 5.0 \(7.0\) at index \(0, 1\)"),
    ],
)
def test_bad_ranges_name_field_and_index(ranges, message):
    with pytest.raises(ValueError, match=message):
        make(ranges=ranges)


def test_over_range_as_max_when_asked():
    s = make(ranges=[[1.0, 7.0, 1.0], [1.0, 1.0, 1.0]], over_range="max")
    assert s.is_max[0, 1] and s.ranges[0, 1] == 5.0
    with pytest.raises(ValueError, match="over_range"):
        make(over_range="clip")


@pytest.mark.parametrize(
    "kw, message",
    [
        (dict(angles=[0.0, 0.1]), "angles has 2 beams"),
        (dict(poses=[[0.0, 0.0]]), "poses must have shape"),
        (dict(poses=[[0.0, 0.0, 0.0]]), "ranges must have shape"),
        (dict(poses=[[0.0, 0.0, 0.0], [np.nan, 0.0, 0.0]]), r"poses has a non-finite value at index \(1, 0\)"),
        (dict(angles=[0.0, np.nan, 0.0]), r"angles has a non-finite value at index \(0, 1\)"),
        (dict(max_range=0.0), "max_range"),
        (dict(max_range=-1.0), "max_range"),
    ],
)
def test_bad_structure(kw, message):
    with pytest.raises(ValueError, match=message):
        make(**kw)


def test_arrays_are_read_only():
    s = make()
    with pytest.raises(ValueError):
        s.ranges[0, 0] = 3.0


def test_one_d():
    s = Scans.one_d([3.0, 4.0], max_range=10.0)
    assert s.num_scans == 2 and s.beams_per_scan == 1
    with pytest.raises(ValueError, match="direction"):
        Scans.one_d([3.0], max_range=10.0, direction=0)


def test_select_takes_scans_by_index_or_mask():
    """``select`` keeps each picked scan whole (pose, per-scan angles, ranges, valid beams), in the order asked,
    and refuses what picks nothing or lies outside."""
    from ogm_ppl import Grid

    poses = np.array([[0.5, 0.5, 0.0], [5.0, 5.0, 1.0], [1.0, 1.5, 2.0]])
    angles = np.array([[0.0, 0.1], [0.2, 0.3], [0.4, 0.5]])
    ranges = np.array([[1.0, 2.0], [3.0, 4.0], [0.5, 9.0]])
    valid = np.array([[True, False], [True, True], [False, True]])
    s = Scans(poses, angles, ranges, 9.0, valid=valid, min_range=0.2)
    two = s.select([2, 0])
    np.testing.assert_array_equal(two.poses, poses[[2, 0]])
    np.testing.assert_array_equal(two.angles, angles[[2, 0]])
    np.testing.assert_array_equal(two.ranges, s.ranges[[2, 0]])
    np.testing.assert_array_equal(two.valid, valid[[2, 0]])
    np.testing.assert_array_equal(two.is_max, s.is_max[[2, 0]])
    assert two.max_range == 9.0 and two.min_range == 0.2
    grid = Grid((40, 40), resolution=0.05)  # 2 m x 2 m: the third scan's pose and the first's
    inside = s.select(grid.contains(poses[:, :2]))
    np.testing.assert_array_equal(inside.poses, poses[[0, 2]])
    np.testing.assert_array_equal(s.select(range(1, 3)).ranges, s.ranges[1:])
    for bad, message in (
        ([], "no scan"),
        ([3], r"\[0, 3\)"),
        ([-1], r"\[0, 3\)"),
        ([0.5], "integers"),
        (np.ones(2, bool), "shape"),
    ):
        with pytest.raises(ValueError, match=message):
            s.select(bad)
