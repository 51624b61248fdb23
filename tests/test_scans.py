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
