"""Candidate stops: pose checks, exact P(path free), geodesic paths and the P(path free) gate."""

import numpy as np
import pytest
from scipy import ndimage

from ogm_ppl import Grid
from ogm_ppl.exploration.candidates import (
    CandidateError,
    PathPlanner,
    check_candidate_poses,
    frontier_mask,
    path_free_probability,
)


def _room(rows=20, cols=30, door=True):
    """A map of two rooms split by a wall at column 15 (p = 0.999), free cells p = 0.001, outer walls occupied."""
    q = np.full((rows, cols), 0.001)
    q[:, 15] = 0.999
    q[[0, -1], :] = q[:, [0, -1]] = 0.999
    if door:
        q[8:13, 15] = 0.001
    return Grid((rows, cols), 0.1), q.ravel()


def test_poses_off_the_grid_inside_an_obstacle_and_empty_are_refused():
    grid, q = _room()
    with pytest.raises(CandidateError, match=r"pose 1 .* off the grid"):
        check_candidate_poses(grid, [[0.5, 0.5, 0.0], [5.0, 0.5, 0.0]])
    with pytest.raises(CandidateError, match=r"pose 0 .* inside an obstacle .*cell \(5, 15\)"):
        check_candidate_poses(grid, [[1.55, 0.55, 0.0]], occupied=q > 0.5)
    with pytest.raises(CandidateError, match="empty"):
        check_candidate_poses(grid, np.zeros((0, 3)))
    with pytest.raises(CandidateError, match="not finite"):
        check_candidate_poses(grid, [[np.nan, 0.5, 0.0]])
    planner = PathPlanner(grid)
    with pytest.raises(CandidateError, match="inside an obstacle"):
        planner.goal_paths([0.55, 1.05, 0.0], [[1.55, 0.55, 0.0]], q)
    with pytest.raises(CandidateError, match="empty"):
        planner.goal_paths([0.55, 1.05, 0.0], np.zeros((0, 3)), q)
    with pytest.raises(CandidateError, match=r"robot pose 0 .* off the grid"):
        planner.goal_paths([-1.0, 1.05, 0.0], [[0.55, 0.55, 0.0]], q)
    with pytest.raises(ValueError, match="zero samples"):
        planner.goal_paths([0.55, 1.05, 0.0], [[0.55, 0.55, 0.0]], q, np.zeros((0, grid.num_cells), np.uint8))


def _swept_brute(grid, path, radius):
    m = np.zeros(grid.num_cells, bool)
    m[path] = True
    r = int(radius)
    dr, dc = np.mgrid[-r : r + 1, -r : r + 1]
    disk = dr**2 + dc**2 <= radius**2 + 1e-9
    return ndimage.binary_dilation(m.reshape(grid.shape), disk).ravel()


@pytest.mark.parametrize("clearance", [0.0, 1.0, 1.5])
def test_path_free_probability_is_exact_for_samples_and_the_product_for_marginals(clearance):
    grid = Grid((12, 14), 0.1)
    rng = np.random.default_rng(3)
    q = rng.uniform(0, 0.2, grid.num_cells)
    samples = (rng.random((200, grid.num_cells)) < q).astype(np.uint8)
    paths = [np.array([15, 16, 30, 44, 45]), np.array([100]), np.array([60, 61, 62, 63, 77, 91])]
    offs = np.concatenate([[0], np.cumsum([len(p) for p in paths])])
    cells = np.concatenate(paths)
    got_s = path_free_probability(grid, offs, cells, samples=samples, clearance_cells=clearance)
    got_q = path_free_probability(grid, offs, cells, marginals=q, clearance_cells=clearance)
    for i, p in enumerate(paths):
        w = _swept_brute(grid, p, clearance)
        assert got_s[i] == np.mean(~samples[:, w].any(1))  # exact: a share of the samples
        assert got_q[i] == pytest.approx(np.prod(1 - q[w]), rel=1e-12)
    with pytest.raises(ValueError, match=r"path_offsets must run from 0 to len\(path_cells\) = 12"):
        path_free_probability(grid, [0, 5], cells, marginals=q)  # offsets of one path, cells of three


def test_paths_are_geodesic_octile_distances_on_an_empty_map():
    grid = Grid((15, 15), 0.05)
    planner = PathPlanner(grid, clearance_cells=0.0, risk_weight=0.0)
    start = 7 * 15 + 7
    goals = np.arange(grid.num_cells)
    goals = goals[goals != start]
    c = planner.paths(start, goals, np.zeros(grid.num_cells))
    r, col = np.divmod(c.cells, 15)
    dx, dy = np.abs(col - 7), np.abs(r - 7)
    octile = (np.maximum(dx, dy) - np.minimum(dx, dy)) + np.sqrt(2) * np.minimum(dx, dy)
    np.testing.assert_allclose(c.distance, octile * 0.05, rtol=1e-12)
    for i in (0, 50, 200):  # each path starts at the start, ends at its goal, and steps to 8-neighbours
        p = c.path(i)
        assert p[0] == start and p[-1] == c.cells[i]
        pr, pc = np.divmod(p, 15)
        assert np.all(np.maximum(np.abs(np.diff(pr)), np.abs(np.diff(pc))) == 1)


def test_the_gate_excludes_candidates_behind_a_wall_and_admits_them_through_a_door():
    start = 10 * 30 + 5
    for door in (False, True):
        grid, q = _room(door=door)
        c = PathPlanner(grid, clearance_cells=1.0).candidates(start, q, threshold=0.9, stride=2)
        beyond = (c.cells % 30) > 15
        assert len(c) > 10 and np.all(c.p_free >= 0.9)
        assert beyond.any() == door
        if door:  # through the door: every path beyond the wall crosses rows 9..11 at column 15
            for i in np.flatnonzero(beyond):
                p = c.path(i)
                assert set(p[p % 30 == 15] // 30) <= {9, 10, 11}


def test_the_gate_uses_the_samples_joint_not_the_marginals():
    """Half the samples close the door: P(path through it free) = 1/2 exactly, whatever the marginals say."""
    grid, q = _room(door=True)
    S = 64
    samples = np.zeros((S, grid.num_cells), np.uint8)
    samples[:] = (q > 0.5).astype(np.uint8)
    samples[: S // 2, [r * 30 + 15 for r in range(8, 13)]] = 1
    qs = samples.mean(0)
    planner = PathPlanner(grid, clearance_cells=1.0)
    start = 10 * 30 + 5
    lo = planner.candidates(start, qs, samples, threshold=0.4, stride=2)
    beyond = (lo.cells % 30) > 15
    assert beyond.any()
    np.testing.assert_array_equal(lo.p_free[beyond], 0.5)
    np.testing.assert_array_equal(lo.p_free[~beyond], 1.0)
    hi = planner.candidates(start, qs, samples, threshold=0.9, stride=2)
    assert not ((hi.cells % 30) > 15).any()


def test_frontier_mask_marks_known_free_cells_next_to_unobserved_ones():
    grid = Grid((6, 6))
    observed = np.zeros((6, 6), bool)
    observed[:, :3] = True
    q = np.full(36, 0.1)
    q[0] = 0.9  # occupied: never a frontier
    f = frontier_mask(grid, q, observed.ravel()).reshape(6, 6)
    expect = np.zeros((6, 6), bool)
    expect[:, 2] = True
    np.testing.assert_array_equal(f, expect)


def test_the_robots_own_disk_is_no_part_of_a_paths_risk():
    """A robot that stopped with a wall cell inside its disk can still drive away from it."""
    grid = Grid((15, 15), 0.1)
    q = np.zeros((15, 15))
    q[7, 6] = 1.0  # next to the robot at (7, 7)
    planner = PathPlanner(grid, clearance_cells=1.0)
    c = planner.candidates(7 * 15 + 7, q.ravel(), threshold=0.9, stride=3)
    assert len(c) > 0 and c.p_free.min() == 1.0
    away = (c.cells % 15) >= 9
    assert away.any()
    # a path that passes the cell's disk later still pays for it
    grid_path = np.array([7 * 15 + 7, 7 * 15 + 8])
    p = path_free_probability(grid, [0, 2], grid_path[::-1], marginals=q.ravel(), clearance_cells=1.0)
    assert p[0] == pytest.approx(1e-9, rel=1e-6)


def test_path_arrays_of_any_layout_and_int_width_run_one_compiled_sweep():
    """Reversed views, int32 offsets and lists give the same answer through one specialisation of the compiled
    swept-set kernel (contiguous int64, the library's index convention)."""
    from ogm_ppl.exploration.candidates import _swept

    grid = Grid((15, 15), 0.1)
    q = np.zeros(225)
    q[7 * 15 + 7] = 0.5
    path = np.array([7 * 15 + 9, 7 * 15 + 8])
    ways = [(np.array([0, 2]), path), (np.array([0, 2], np.int32), path[::-1]), ([0, 2], list(path))]
    p = [path_free_probability(grid, offs, cells, marginals=q, clearance_cells=1.0) for offs, cells in ways]
    # the cell at (7, 7), next to the path, is in its swept set: P(free) = 1 - 0.5 exactly
    assert p[0][0] == 0.5 and p[1][0] == 0.5 and p[2][0] == 0.5
    assert len(_swept.signatures) == 1, _swept.signatures


def test_a_start_or_goal_cell_off_the_grid_is_refused_not_followed():
    """A flat start cell of a pose just off the grid (negative) sent Dijkstra's path tracing into an endless loop
    or a crash; a pose given where a cell is meant and a goal cell past the end are refused too."""
    grid, q = _room()
    planner = PathPlanner(grid)
    with pytest.raises(CandidateError, match=r"start_cell -60 lies off the grid \(cells 0..599\)"):
        planner.candidates(-60, q, threshold=0.5)
    with pytest.raises(CandidateError, match="start_cell -1 lies off the grid"):
        planner.paths(-1, [35, 36], q)
    with pytest.raises(CandidateError, match=r"start_cell must be one flat cell index .*goal_paths takes the robot"):
        planner.candidates(np.array([1.0, 1.0, 0.0]), q)
    with pytest.raises(CandidateError, match="goal cell 600 lies off the grid"):
        planner.paths(35, [36, 600], q)
    assert planner.paths(np.int64(35), [37], q).distance.size == 1
