import dataclasses
import itertools
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ogm_ppl import Grid, Scans, raycast
from ogm_ppl.raycast import ray_inputs
from ogm_ppl.reference import _crossings, reading_kappa_reference, traverse_reference

ROWS, COLS = 23, 31


def one_ray(u0, v0, theta, rng, max_range, grid=None):
    grid = grid or Grid((ROWS, COLS), resolution=1.0)
    scans = Scans(poses=[[u0, v0, theta]], angles=[0.0], ranges=[[rng]], max_range=max_range)
    return raycast(grid, scans)


ray_args = dict(
    u0=st.floats(0.0, COLS, exclude_max=True, allow_nan=False),
    v0=st.floats(0.0, ROWS, exclude_max=True, allow_nan=False),
    theta=st.floats(-2 * math.pi, 2 * math.pi, allow_nan=False),
    frac=st.floats(0.0, 1.0),
    max_range=st.floats(0.01, 60.0),
)


@settings(max_examples=1500)
@given(**ray_args)
def test_traversal_properties(u0, v0, theta, frac, max_range):
    rng = frac * max_range
    rays = one_ray(u0, v0, theta, rng, max_range)
    cells = rays.ray(0)
    rows, cols = np.divmod(cells, COLS)
    # starts in the pose's cell
    assert cells[0] == math.floor(v0) * COLS + math.floor(u0)
    # consecutive cells are 4-connected
    steps = np.abs(np.diff(rows)) + np.abs(np.diff(cols))
    assert np.all(steps == 1)
    # no cell twice; entry distances increase from 0 and stay below max range
    assert len(set(cells.tolist())) == len(cells)
    t = rays.t_enter[rays.offsets[0] : rays.offsets[1]].astype(float)
    # t_enter is float32: below max range up to its rounding
    assert t[0] == 0.0 and np.all(np.diff(t) >= 0) and np.all(t <= max_range * (1 + 1e-6))
    # the reading's kappa: the cell whose entry distance is nearest to it (ties to the nearer), counted
    # on past the grid edge; compared with the reference built from the sorted list of every crossing
    ts = [0.0] + sorted(_crossings(u0, math.cos(theta), max_range) + _crossings(v0, math.sin(theta), max_range))
    assert rays.range_len[0] == len(ts) >= len(cells)
    if rng < max_range:
        mids = [0.5 * (a + b) for a, b in itertools.pairwise(ts)]
        if min((abs(m - rng) for m in mids), default=1.0) > 1e-6:  # no floating-point tie
            z_ref = reading_kappa_reference(u0, v0, math.cos(theta), math.sin(theta), max_range, rng)
            assert rays.z[0] == z_ref
            assert abs(ts[z_ref] - rng) <= min(abs(t - rng) for t in ts) + 1e-9
            assert rays.endpoint_in_grid[0] == (z_ref < len(cells))
    else:
        assert rays.is_max[0] and rays.z[0] == len(cells)


@settings(max_examples=1500)
@given(**ray_args)
def test_traversal_matches_reference(u0, v0, theta, frac, max_range):
    rays = one_ray(u0, v0, theta, frac * max_range, max_range)
    ref_cells, ref_t = traverse_reference(u0, v0, math.cos(theta), math.sin(theta), max_range, ROWS, COLS)
    np.testing.assert_array_equal(rays.ray(0), ref_cells)
    np.testing.assert_allclose(rays.t_enter[rays.offsets[0] : rays.offsets[1]], ref_t, rtol=1e-6, atol=1e-5)


def test_thousands_of_random_rays_match_reference():
    rng = np.random.default_rng(1)
    S, B = 40, 100
    grid = Grid((ROWS, COLS), resolution=0.25, origin=(-2.0, 1.0))
    poses = np.c_[
        rng.uniform(-2, -2 + COLS * 0.25, S), rng.uniform(1, 1 + ROWS * 0.25, S), rng.uniform(-np.pi, np.pi, S)
    ]
    angles = rng.uniform(-np.pi, np.pi, (S, B))
    scans = Scans(poses, angles, rng.uniform(0, 9.0, (S, B)), max_range=8.0, over_range="max")
    rays = raycast(grid, scans)
    uv = grid.world_to_continuous(poses[:, :2])
    th = scans.world_angles()
    checked = 0
    for s in range(S):
        for b in range(B):
            ref, _ = traverse_reference(
                uv[s, 0], uv[s, 1], math.cos(th[s, b]), math.sin(th[s, b]), 8.0 / 0.25, ROWS, COLS
            )
            np.testing.assert_array_equal(rays.ray(s * B + b), ref)
            checked += 1
    assert checked == 4000


def test_axis_aligned_and_corner_rays():
    # along a row, along a column, and exactly through grid corners (ties step the column first)
    r = one_ray(0.5, 0.5, 0.0, 3.0, 4.0)
    assert r.ray(0).tolist() == [0, 1, 2, 3, 4] and r.z[0] == 3
    r = one_ray(0.5, 0.5, math.pi / 2, 2.0, 3.0)
    assert r.ray(0).tolist() == [0, COLS, 2 * COLS, 3 * COLS]
    r = one_ray(0.0, 0.0, math.pi / 4, 2.0, 2.0)
    rows, cols = np.divmod(r.ray(0), COLS)
    assert np.all(np.abs(np.diff(rows)) + np.abs(np.diff(cols)) == 1)


def test_cut_at_grid_edge_and_hits_beyond():
    grid = Grid((1, 10), resolution=1.0)
    scans = Scans(poses=[[7.5, 0.5, 0.0]] * 3, angles=[0.0], ranges=[[1.0], [5.0], [20.0]], max_range=20.0)
    rays = raycast(grid, scans)
    assert rays.ray(1).tolist() == [7, 8, 9]
    assert rays.endpoint_in_grid.tolist() == [True, False, False]
    assert rays.z.tolist() == [1, 5, 3]  # kappa of a hit beyond the edge is counted on
    assert rays.is_max.tolist() == [False, False, True]


def test_one_d_rays_and_thesis_kappa():
    grid = Grid.line(15)
    rays = raycast(grid, Scans.one_d([11.0, 7.0, 0.0, 14.0], max_range=14.0))
    assert rays.z.tolist() == [11, 7, 0, 15]  # the last is a max-range reading: z = ray length
    assert rays.is_max.tolist() == [False, False, False, True]
    assert rays.ray(0).tolist() == list(range(15))
    back = raycast(grid, Scans.one_d([3.0], max_range=5.0, position=9.5, direction=-1))
    assert back.ray(0).tolist() == [9, 8, 7, 6, 5, 4] and back.z[0] == 3


def test_transposed_index_is_consistent():
    rng = np.random.default_rng(3)
    grid = Grid((20, 20), resolution=1.0)
    scans = Scans(
        np.c_[rng.uniform(0, 20, 5), rng.uniform(0, 20, 5), np.zeros(5)],
        rng.uniform(-3, 3, 50),
        rng.uniform(0, 12, (5, 50)),
        max_range=10.0,
        over_range="max",
    )
    rays = raycast(grid, scans)
    idx = rays.by_cell
    assert idx.offsets[-1] == rays.nnz
    for k in range(grid.num_cells):
        rr = idx.ray[idx.offsets[k] : idx.offsets[k + 1]]
        kk = idx.kappa[idx.offsets[k] : idx.offsets[k + 1]]
        assert np.all(np.diff(rr) >= 0)
        assert np.all(rays.cells[rays.offsets[rr] + kk] == k)
    assert np.all(rays.cells[rays.offsets[rays.ray_of_entry] + rays.kappa] == rays.cells)


def test_reached_and_endpoints():
    grid = Grid.line(10)
    rays = raycast(grid, Scans.one_d([3.0, 9.0], max_range=9.0))
    assert rays.reached().tolist() == [True] * 10  # the max-range ray reaches everything
    rays = raycast(grid, Scans.one_d([3.0], max_range=9.0))
    assert rays.reached().tolist() == [True] * 4 + [False] * 6
    assert rays.endpoint_cells().tolist() == [3]


@pytest.mark.parametrize(
    "pose, message",
    [([31.0, 1.0, 0.0], r"poses\[1\]"), ([-0.1, 1.0, 0.0], r"poses\[1\]"), ([3.0, 23.5, 0.0], r"poses\[1\]")],
)
def test_pose_outside_grid(pose, message):
    grid = Grid((ROWS, COLS))
    scans = Scans([[1.0, 1.0, 0.0], pose], [0.0], [[1.0], [1.0]], max_range=5.0)
    with pytest.raises(ValueError, match=message):
        raycast(grid, scans)


def test_one_d_rejects_oblique_beams():
    with pytest.raises(ValueError, match="along the row"):
        raycast(Grid.line(10), Scans([[0.5, 0.0, 0.3]], [0.0], [[1.0]], max_range=5.0))


# ------------------------ ray count, past the edge, capacity, identity, errors


def _scans(n_rays: int = 7, max_range: float = 40.0) -> tuple[Grid, Scans]:
    rng = np.random.default_rng(11)
    grid = Grid((9, 13), resolution=1.0)
    poses = [[2.3, 5.7, 0.0], [10.6, 1.2, 2.0]]
    angles = rng.uniform(-math.pi, math.pi, n_rays)
    ranges = rng.uniform(0.5, max_range * 1.2, (2, n_rays))
    return grid, Scans(poses, angles, ranges, max_range=max_range, over_range="max")


def test_num_rays_and_default_reading_index():
    grid, scans = _scans()
    rays = raycast(grid, scans)
    assert rays.num_rays == 14 == len(rays.z)
    np.testing.assert_array_equal(rays.reading, np.arange(14))


def test_entries_beyond_edge_match_the_reference_crossings():
    """Past the grid edge each ray's entry distances are the crossings of an unbounded grid, from the
    ray's own start ``(u0, v0)`` (here ``u0 != v0`` everywhere), up to max range."""
    grid, scans = _scans()
    rays = raycast(grid, scans)
    ri = ray_inputs(grid, scans)
    off, t = rays.entries_beyond_edge(np.arange(rays.num_rays))
    assert off[0] == 0 and len(off) == rays.num_rays + 1
    cut = 0
    for r in range(rays.num_rays):
        u0, v0, du, dv, L = ri.u0[r], ri.v0[r], ri.du[r], ri.dv[r], ri.length[r]
        assert u0 != v0
        ts = [0.0, *sorted(_crossings(u0, du, L) + _crossings(v0, dv, L))]
        n_in = rays.offsets[r + 1] - rays.offsets[r]
        np.testing.assert_allclose(t[off[r] : off[r + 1]], ts[n_in:], rtol=1e-5, atol=1e-5)
        cut += len(ts) > n_in
    assert cut >= 5  # most rays leave the grid before max range


@pytest.mark.parametrize("angle", [0.0, 0.3, math.pi / 4, 1.2, math.pi / 2, 2.5])
def test_capacity_bounds_every_ray(angle):
    """``RayInputs.capacity()`` bounds the cells of every ray and every reading's kappa, on an unbounded
    grid too (``range_len``), for long rays at any angle."""
    grid = Grid((80, 80), resolution=1.0)
    scans = Scans([[40.5, 40.5, angle]], [0.0, 0.1, -0.1], [[35.0, 39.0, 38.0]], max_range=38.0, over_range="max")
    rays = raycast(grid, scans)
    cap = ray_inputs(grid, scans).capacity()
    assert cap >= int(np.diff(rays.offsets).max())
    assert cap >= int(rays.range_len.max()) and cap >= int(rays.z.max())


def test_rays_compare_by_identity():
    """``Rays`` hold arrays: equality is identity (two casts of the same scans are different objects)
    and they can be used as dictionary keys."""
    grid, scans = _scans(3)
    a, b = raycast(grid, scans), raycast(grid, scans)
    assert a == a and a != b
    assert len({a: 1, b: 2}) == 2


def test_transposed_index_is_immutable():
    grid, scans = _scans(3)
    idx = raycast(grid, scans).by_cell
    with pytest.raises(dataclasses.FrozenInstanceError):
        idx.offsets = idx.offsets.copy()


def test_error_names_the_first_pose_outside_the_grid():
    grid = Grid((5, 5), resolution=1.0)
    scans = Scans([[1.0, 1.0, 0.0], [9.0, 1.0, 0.0], [1.0, 9.0, 0.0]], [0.0], [[1.0]] * 3, max_range=3.0)
    with pytest.raises(ValueError, match=r"poses\[1\]"):
        raycast(grid, scans)


@pytest.mark.parametrize("max_range", [0.3, 3.0, 8.0, 40.0])
def test_ray_cast_size_bounds_the_cast_before_it_runs(max_range):
    """What :func:`ray_cast_size` says before a cast: the rays exactly, an upper bound on the ray-cell entries
    within 3 a ray, on the longest ray, and the capacity the cast allocates (at least the entries), for random
    rays on a 2D grid and on a line."""
    from ogm_ppl.raycast import CAST_BYTES_PER_CELL, CAST_BYTES_PER_RAY, ray_cast_size

    rng = np.random.default_rng(7)
    S, B = 30, 60
    grid = Grid((ROWS, COLS), resolution=0.25, origin=(-2.0, 1.0))
    poses = np.c_[
        rng.uniform(-2, -2 + COLS * 0.25, S), rng.uniform(1, 1 + ROWS * 0.25, S), rng.uniform(-np.pi, np.pi, S)
    ]
    angles = np.where(rng.random((S, B)) < 0.1, 0.0, rng.uniform(-np.pi, np.pi, (S, B)))  # some along an axis
    scans = Scans(poses, angles, rng.uniform(0, 1.2 * max_range, (S, B)), max_range=max_range, over_range="max")
    line = Grid.line(50)
    for g, sc in (
        (grid, scans),
        (line, Scans.one_d(rng.uniform(0, max_range * 5, 40).tolist(), max_range=max_range * 5)),
    ):
        size = ray_cast_size(g, sc)
        rays = raycast(g, sc)
        assert size.rays == rays.num_rays
        assert rays.nnz <= size.crossings <= rays.nnz + 3 * rays.num_rays
        assert size.longest >= rays.lengths.max() and size.capacity >= size.crossings
        assert size.cast_bytes == size.capacity * CAST_BYTES_PER_CELL + size.rays * CAST_BYTES_PER_RAY
