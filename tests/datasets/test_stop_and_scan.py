"""Stop-and-scan datasets (Section 6.1): the exploration route and the simulated scans."""

import numpy as np
import pytest
from scipy import ndimage

from ogm_ppl import Grid
from ogm_ppl.datasets.stop_and_scan import StopAndScan, drive_route, plan_route, route_coverage, stop_and_scan

F = 30  # a smaller range than the thesis's 75 cells, so that a 120 x 120 map needs several stops


def rooms_map(n: int = 120) -> np.ndarray:
    """Four rooms off a corridor, doors 10 cells wide, a block in one room and a closed closet."""
    m = np.zeros((n, n), dtype=bool)
    m[:3, :] = m[-3:, :] = m[:, :3] = m[:, -3:] = True  # outer wall
    m[50:52, :] = m[68:70, :] = True  # corridor walls (rows 52..67 free)
    m[:50, 60:62] = m[70:, 60:62] = True  # room partitions
    for c in (20, 85):  # doors from the corridor into the four rooms
        m[50:52, c : c + 10] = m[68:70, c : c + 10] = False
    m[20:30, 20:28] = True  # a block in the lower-left room
    m[95:, 100:102] = m[95:97, 100:] = True  # a closed closet (unreachable free space)
    return m


@pytest.fixture(scope="module")
def world():
    truth = rooms_map()
    return truth, Grid(truth.shape, resolution=0.05)


@pytest.fixture(scope="module")
def route(world):
    truth, grid = world
    return plan_route(truth, grid, max_range_cells=F, seed=3)


def test_route_is_seeded(world, route):
    truth, grid = world
    np.testing.assert_array_equal(route, plan_route(truth, grid, max_range_cells=F, seed=3))
    other = plan_route(truth, grid, max_range_cells=F, seed=4)
    assert not (other.shape == route.shape and np.array_equal(other, route))


def test_poses_are_free_clear_inside_and_connected(world, route):
    truth, grid = world
    assert route.ndim == 2 and route.shape[1] == 3 and len(route) >= 4
    assert grid.contains(route[:, :2]).all()
    cells = grid.world_to_cell(route[:, :2])
    assert not truth[cells[:, 0], cells[:, 1]].any()
    clear = ndimage.distance_transform_edt(np.pad(~truth, 1))[1:-1, 1:-1]
    assert (clear[cells[:, 0], cells[:, 1]] > 2).all()
    lab, _ = ndimage.label(clear > 2, structure=np.ones((3, 3)))
    assert len(np.unique(lab[cells[:, 0], cells[:, 1]])) == 1  # all reachable from the start
    assert not (cells[:, 0] >= 97).__and__(cells[:, 1] >= 102).any()  # never inside the closed closet


def test_coverage_is_reached(world, route):
    truth, grid = world
    assert route_coverage(truth, grid, route, max_range_cells=F) >= 0.95
    # the route stops once covered: without its last stop the coverage was still short
    assert route_coverage(truth, grid, route[:-1], max_range_cells=F) < 0.95


@pytest.mark.parametrize("pad", [0, 90])
def test_the_windowed_frontier_search_plans_the_whole_grid_route(world, monkeypatch, pad):
    """Goals are searched in the known-free cells' window grown by the reach; the route equals the one the
    whole-grid search plans, with the window at the grid's edge (pad 0) and well inside it (the rooms in a
    larger grid of occupied cells)."""
    import functools
    import importlib

    sas = importlib.import_module("ogm_ppl.datasets.stop_and_scan")  # the module, not its function

    truth, _ = world
    big = np.pad(truth, pad, constant_values=True)
    grid = Grid(big.shape, resolution=0.05)
    windowed = plan_route(big, grid, max_range_cells=F, seed=5)
    monkeypatch.setattr(sas, "_next_goal", functools.partial(sas._next_goal, whole_grid=True))
    whole = plan_route(big, grid, max_range_cells=F, seed=5)
    assert len(windowed) >= 4
    np.testing.assert_array_equal(windowed, whole)


def test_num_poses_and_start(world):
    truth, grid = world
    short = plan_route(truth, grid, max_range_cells=F, num_poses=3, seed=3)
    assert len(short) == 3
    r = plan_route(truth, grid, max_range_cells=F, start=(1.0, 3.0, 0.5), num_poses=2)
    np.testing.assert_array_equal(r[0], [1.0, 3.0, 0.5])
    low = plan_route(truth, grid, max_range_cells=F, coverage=0.3, seed=3)
    assert route_coverage(truth, grid, low, max_range_cells=F) >= 0.3
    assert route_coverage(truth, grid, low[:-1], max_range_cells=F) < 0.3


def test_default_dataset_is_the_thesis_setting(world):
    truth, grid = world
    d = stop_and_scan(truth, grid, num_poses=2, seed=1)
    assert isinstance(d, StopAndScan)
    assert d.scans.beams_per_scan == 720 and d.scans.num_scans == len(d.route) == 2
    np.testing.assert_allclose(np.diff(d.scans.angles[0]), np.deg2rad(0.5))
    assert d.scans.max_range == pytest.approx(75 * 0.05)
    assert d.settings["sigma_cells"] == 3.0 and d.settings["max_range_cells"] == 75
    np.testing.assert_array_equal(d.scans.poses, d.route)


def test_dataset_is_seeded(world, route):
    truth, grid = world
    a = stop_and_scan(truth, grid, route=route, max_range_cells=F, seed=5)
    b = stop_and_scan(truth, grid, route=route, max_range_cells=F, seed=5)
    c = stop_and_scan(truth, grid, route=route, max_range_cells=F, seed=6)
    np.testing.assert_array_equal(a.scans.ranges, b.scans.ranges)
    assert not np.array_equal(a.scans.ranges, c.scans.ranges)
    planned = stop_and_scan(truth, grid, max_range_cells=F, seed=3, beam_step=8)
    np.testing.assert_array_equal(planned.route, route)  # the route of the same seed


def test_sparser_variants_are_subsets(world, route):
    truth, grid = world
    full = stop_and_scan(truth, grid, route=route, max_range_cells=F, seed=2)
    sparse = stop_and_scan(truth, grid, route=route, max_range_cells=F, seed=2, pose_fraction=0.5, beam_step=4)
    idx = np.asarray(sparse.settings["pose_indices"])
    assert len(idx) == round(0.5 * len(route)) and idx[0] == 0 and idx[-1] == len(route) - 1
    assert np.all(np.diff(idx) > 0)
    np.testing.assert_array_equal(sparse.route, full.route)
    np.testing.assert_array_equal(sparse.scans.poses, full.scans.poses[idx])
    np.testing.assert_array_equal(sparse.scans.angles[0], full.scans.angles[0, ::4])
    np.testing.assert_array_equal(sparse.scans.ranges, full.scans.ranges[idx][:, ::4])
    assert sparse.scans.beams_per_scan == 180


def test_readings_match_the_truth(world, route):
    truth, grid = world
    d = stop_and_scan(truth, grid, route=route, max_range_cells=F, sigma_cells=1e-6, seed=0)
    s = d.scans
    hit = ~s.is_max
    assert hit.mean() > 0.5
    theta = s.world_angles()[hit]
    xy = np.repeat(s.poses[:, None, :2], s.beams_per_scan, 1)[hit]
    end = xy + s.ranges[hit][:, None] * np.stack([np.cos(theta), np.sin(theta)], 1)
    cells = np.clip(grid.world_to_cell(end), 0, np.array(truth.shape) - 1)
    near_wall = ndimage.binary_dilation(truth, structure=np.ones((3, 3)))
    assert near_wall[cells[:, 0], cells[:, 1]].all()
    # a max-range reading is max-range because nothing is closer than F in that direction
    assert s.ranges[s.is_max] == pytest.approx(F * grid.resolution)


def test_bad_input_raises(world):
    truth, grid = world
    with pytest.raises(ValueError, match="shape"):
        plan_route(truth[:-1], grid)
    with pytest.raises(ValueError, match="shape"):
        stop_and_scan(truth[:, :-1], grid)
    with pytest.raises(ValueError, match="no free cell"):
        plan_route(np.ones_like(truth), grid)
    with pytest.raises(ValueError, match="occupied"):
        plan_route(truth, grid, start=(0.05, 0.05))  # inside the outer wall
    with pytest.raises(ValueError, match="clearance"):
        plan_route(truth, grid, start=(0.2, 0.2))  # free, but beside the wall
    with pytest.raises(ValueError, match="outside"):
        plan_route(truth, grid, start=(-1.0, 2.0))
    with pytest.raises(ValueError, match="sigma"):
        stop_and_scan(truth, grid, num_poses=1, sigma_cells=-1.0)
    with pytest.raises(ValueError, match="coverage"):
        plan_route(truth, grid, coverage=1.5)
    with pytest.raises(ValueError, match="pose_fraction"):
        stop_and_scan(truth, grid, num_poses=1, pose_fraction=0.0)
    with pytest.raises(ValueError, match="beam_step"):
        stop_and_scan(truth, grid, num_poses=1, beam_step=0)
    with pytest.raises(ValueError, match="occupied"):
        stop_and_scan(truth, grid, route=[[0.05, 0.05, 0.0]])
    tiny = np.zeros((4, 4), bool)
    with pytest.raises(ValueError, match="clearance"):
        plan_route(tiny, Grid((4, 4)))


# --------------------------------------------------------------------------- drive_route
def test_drive_route_follows_clear_paths_through_every_stop(world, route):
    truth, grid = world
    step = 7.0
    poses = drive_route(truth, grid, route, step_cells=step)
    cells = grid.world_to_cell(poses[:, :2])
    clear = ndimage.distance_transform_edt(np.pad(~truth, 1))[1:-1, 1:-1]
    assert (clear[cells[:, 0], cells[:, 1]] > 2).all()  # every pose keeps the planner's clearance
    # consecutive poses are step_cells of path apart: never further apart in a straight line
    gaps = np.hypot(*np.diff(poses[:, :2], axis=0).T) / grid.resolution
    assert gaps.max() <= step + 1.0 and gaps.min() > 0
    # the route's first and last stops are driven through, at their cell centres
    ends = grid.cell_to_world(grid.world_to_cell(route[[0, -1], :2]))
    np.testing.assert_allclose(poses[[0, -1], :2], ends)
    # every stop lies on the path: within half a step (plus a diagonal cell) of a pose
    d = np.hypot(*(poses[None, :, :2] - route[:, None, :2]).transpose(2, 0, 1)).min(axis=1) / grid.resolution
    assert d.max() <= step / 2 + np.sqrt(2)
    # the yaw faces the next pose wherever the path runs straight between them
    nxt = np.arctan2(*np.diff(poses[:, :2], axis=0)[:, ::-1].T)
    err = np.abs(np.angle(np.exp(1j * (poses[:-1, 2] - nxt))))
    assert np.median(err) < 0.2
    # a denser drive has more poses, and a step longer than the path leaves the two ends
    assert len(drive_route(truth, grid, route, step_cells=2.0)) > 3 * len(poses)
    two = drive_route(truth, grid, route[:2], step_cells=1e6)
    assert two.shape == (2, 3)


def test_drive_route_faces_the_way_it_drives_at_any_step():
    """Every pose faces the next cell of the path, whatever the step: driving west at one cell a pose faces
    yaw pi (the last pose keeps its predecessor's), a diagonal drive at one cell a pose faces pi / 4 and visits
    each path cell once."""
    t = np.zeros((20, 20), bool)
    t[[0, -1], :] = t[:, [0, -1]] = True
    g = Grid((20, 20), 1.0)
    for step in (0.5, 1.0, 2.0):
        west = drive_route(t, g, [[14.5, 4.5], [4.5, 4.5]], step_cells=step)
        np.testing.assert_allclose(np.abs(west[:, 2]), np.pi)
        assert (np.diff(west[:, 0]) < 0).all()  # one pose per cell at most, in the order driven
    diag = drive_route(t, g, [[4.5, 4.5], [12.5, 12.5]], step_cells=1.0)
    np.testing.assert_allclose(diag[:, 2], np.pi / 4)
    assert len(np.unique(diag[:, :2], axis=0)) == len(diag)
    one = drive_route(t, g, [[4.5, 4.5], [4.5, 4.5]], step_cells=3)
    np.testing.assert_allclose(one, [[4.5, 4.5, 0.0]])


def test_drive_route_takes_detours_longer_than_its_first_search():
    """Two stops 6 cells apart either side of a long wall: the path runs round the wall's end (over 2 x 6 + 50
    cells of path, beyond the bounded first search) and is the shortest one."""
    t = np.zeros((40, 160), bool)
    t[[0, -1], :] = t[:, [0, -1]] = True
    t[20, :150] = True  # a wall open only at its east end
    g = Grid(t.shape, 1.0)
    poses = drive_route(t, g, [[5.5, 17.5], [5.5, 23.5]], step_cells=1.0)
    cells = g.world_to_cell(poses[:, :2])
    assert cells[:, 1].max() >= 150  # round the wall's end
    assert not t[cells[:, 0], cells[:, 1]].any()
    path = np.hypot(*np.diff(poses[:, :2], axis=0).T).sum()
    # the shortest clear path: east along row 17, round the end at clearance 3, back west along row 23
    assert path < 2 * (150 + 3 - 5) + 6 + 4 * (np.sqrt(2) - 1) * 3 + 1e-9


def test_drive_route_poses_scan_with_the_stops_simulator(world, route):
    """Front-facing scans simulate at the driven poses, and the driven poses' 360-degree coverage is at least
    the stops' (the path passes through every stop)."""
    from ogm_ppl.datasets.simulate import simulate_scans

    truth, grid = world
    poses = drive_route(truth, grid, route, step_cells=10)
    front = np.linspace(-np.pi / 2, np.pi / 2, 91)
    s = simulate_scans(grid, truth, poses, front, F * grid.resolution, 0.5, seed=0)
    assert s.ranges.shape == (len(poses), 91)
    assert (
        route_coverage(truth, grid, poses, max_range_cells=F)
        >= route_coverage(truth, grid, route, max_range_cells=F) - 1e-12
    )


def test_drive_route_bad_input(world, route):
    truth, grid = world
    with pytest.raises(ValueError, match="step_cells"):
        drive_route(truth, grid, route, step_cells=0)
    with pytest.raises(ValueError, match="shape"):
        drive_route(truth, grid, np.zeros((2, 4)), step_cells=3)
    with pytest.raises(ValueError, match="outside the grid"):
        drive_route(truth, grid, [[-1.0, 1.0]], step_cells=3)
    with pytest.raises(ValueError, match="clearance"):
        drive_route(truth, grid, [[0.1, 0.1]], step_cells=3)  # the outer wall's corner
    closet = grid.cell_to_world(np.array([[105, 110]]))[0]  # free, clear, walled off
    with pytest.raises(ValueError, match="cannot be reached"):
        drive_route(truth, grid, [route[0, :2], closet], step_cells=3)
