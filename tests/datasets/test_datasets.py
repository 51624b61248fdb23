import numpy as np
import pytest

from ogm_ppl import Grid, raycast
from ogm_ppl.datasets import (
    THESIS_TOY_READINGS,
    first_hit,
    simple_2d_example,
    simulate_scans,
    toy_1d,
)


def test_toy_is_seeded_and_rounded():
    a, b, c = toy_1d(seed=3, num_readings=50), toy_1d(seed=3, num_readings=50), toy_1d(seed=4, num_readings=50)
    np.testing.assert_array_equal(a.readings, b.readings)
    assert not np.array_equal(a.readings, c.readings)
    assert np.all(a.readings == np.rint(a.readings))
    assert abs(a.readings.mean() - 8) < 4 * 3 / np.sqrt(50)
    t = toy_1d(readings=THESIS_TOY_READINGS)
    assert t.truth.tolist() == [False] * 8 + [True] * 12
    with pytest.raises(ValueError, match="wall"):
        toy_1d(num_cells=5, wall=5)


def test_simulation_without_noise_is_exact():
    grid = Grid((1, 20), resolution=0.5)
    truth = np.zeros((1, 20), bool)
    truth[0, 12] = True
    s = simulate_scans(grid, truth, [[1.25, 0.25, 0.0], [1.25, 0.25, np.pi]], [0.0], 8.0, 0.0)
    # wall entered at x = 6.0 m from x = 1.25 m; looking back, nothing inside the grid: max range
    np.testing.assert_allclose(s.ranges[:, 0], [4.75, 8.0])
    assert s.is_max[:, 0].tolist() == [False, True]


def test_simple_example_matches_the_thesis_setting():
    ex = simple_2d_example()
    assert ex.scans.num_scans == 3 and ex.scans.beams_per_scan == 720
    np.testing.assert_allclose(np.diff(ex.scans.angles[0])[:3], np.deg2rad(0.5))
    assert 0 < ex.scans.is_max.mean() < 0.5  # some beams without a return
    rays = raycast(ex.grid, ex.scans)
    upper_right = np.zeros(ex.grid.shape, bool)
    upper_right[41:, 45:] = True
    assert not rays.reached()[upper_right.ravel()].any()  # the closed room is never reached
    # readings scatter about the true first hit with sigma = 3 cells
    probe = raycast(
        ex.grid,
        type(ex.scans)(ex.scans.poses, ex.scans.angles[0], np.full((3, 720), ex.scans.max_range), ex.scans.max_range),
    )
    f = first_hit(probe, ex.truth)
    hit = (f < probe.lengths) & ~rays.is_max
    true_range = probe.t_enter[probe.offsets[:-1][hit] + f[hit]]
    err = rays.range_cells[hit] - true_range
    assert abs(err.std() - 3.0) < 0.3
