"""The active-mapping loop: reproducible from its seed, nearest-frontier choice, empty candidate sets, bad
starts, the information rules, and the rebuild mapper's chain."""

import json

import numpy as np
import pytest
import torch

from ogm_ppl import GaussianRange, Grid
from ogm_ppl.datasets.mapgen import generate_map
from ogm_ppl.exploration.active import (
    Method,
    OGMMapper,
    RebuildMapper,
    Robot,
    _choose,
    explore,
    path_to,
)
from ogm_ppl.exploration.candidates import CandidateError, PathPlanner
from ogm_ppl.priors import IndependentPrior

ROBOT = Robot(beams=60, max_range_cells=12, sigma_cells=1.0, samples=8, sweeps=2, stride=4)


@pytest.fixture(scope="module")
def office():
    truth = generate_map("office", (64, 64), seed=1, border=4)
    return truth, Grid(truth.shape, 0.05)


def _strip(records):
    """The records without their wall times, as JSON (NaN equals NaN there)."""
    return json.dumps([{k: v for k, v in r.items() if k != "seconds"} for r in records], sort_keys=True)


@pytest.mark.parametrize(
    "method",
    [
        Method("frontier", "frontier"),
        Method("ogm", "ogm_info"),
        Method("ind", "sample_info", prior="independent"),
        Method("cov", "sample_coverage", prior="independent", per_metre=True),
    ],
    ids=lambda m: m.name,
)
def test_the_loop_is_reproducible_from_its_seed(office, method):
    truth, grid = office
    a = explore(truth, grid, method, ROBOT, stops=4, seed=5)
    b = explore(truth, grid, method, ROBOT, stops=4, seed=5)
    assert _strip(a.records) == _strip(b.records)
    np.testing.assert_array_equal(a.route, b.route)
    np.testing.assert_array_equal(a.maps, b.maps)
    c = explore(truth, grid, method, ROBOT, stops=4, seed=6)
    assert c.settings["start"] != a.settings["start"] or not np.array_equal(c.maps, a.maps)
    # the records are what the docs say: coverage grows, the path length too
    cov = [r["coverage"] for r in a.records]
    dist = [r["path_length"] for r in a.records]
    assert np.all(np.diff(cov) >= 0) and np.all(np.diff(dist) > 0) and len(a.records) == 4
    assert all(0 <= r["f1"] <= 1 and r["nll_bits"] > 0 for r in a.records)


def test_an_information_rule_moves_the_robot_to_more_new_cells_than_the_nearest_frontier(office):
    """Not a benchmark, a sanity check on one map: after 4 stops the gain rules have covered at least as much."""
    truth, grid = office
    fr = explore(truth, grid, Method("frontier", "frontier"), ROBOT, stops=4, seed=0)
    ig = explore(truth, grid, Method("ogm", "ogm_info"), ROBOT, stops=4, seed=0)
    assert ig.records[-1]["coverage"] >= fr.records[-1]["coverage"]


def _frontier_scene():
    """30 x 30, all observed and free except: a wall at column 10 (rows 0..24, the gap below it), an unobserved
    pocket A right of the wall (rows 12..17, cols 13..18) and an unobserved pocket B top left (rows 0..4,
    cols 0..8). From the robot at (15, 4) A is nearer as the crow flies (9 cells) than B (10.8 cells), but
    reachable only round the wall's end (about 30 cells), B directly (about 11 cells)."""
    grid = Grid((30, 30), 0.05)
    q = np.full((30, 30), 0.05)
    q[:25, 10] = 0.95
    observed = np.ones((30, 30), bool)
    observed[12:18, 13:19] = False
    observed[0:5, 0:9] = False
    q[~observed] = 0.5
    return grid, q.ravel(), observed.ravel()


def test_nearest_frontier_picks_the_geodesically_nearest_reachable_frontier():
    grid, q, observed = _frontier_scene()
    robot = Robot(clearance_cells=1.0, min_step_cells=2.0)
    planner = PathPlanner(grid, robot.clearance_cells, robot.risk_weight)
    start = 15 * 30 + 4
    j, cand, _ = _choose(
        Method("frontier", "frontier"), robot, planner, grid, start, q, q, None, observed, [], GaussianRange(1.0),
        np.zeros(4), 0.5, 0.5,
    )  # fmt: skip
    assert j is not None
    r, c = divmod(int(cand.cells[j]), 30)
    assert r <= 7 and c <= 10  # next to pocket B
    assert cand.distance[j] == cand.distance[cand.frontier].min()
    # reference: geodesic distances through cells whose disk is free on the thresholded map
    known = np.where(observed & (q < 0.5), 0.0, 1.0)
    ref = PathPlanner(grid, 1.0, risk_weight=1e6)  # a risky step costs more than any detour
    d, _ = ref.distances(start, known)
    goals = cand.cells[cand.frontier]
    assert cand.distance[j] == pytest.approx(d[goals].min() * 0.05, rel=1e-9)
    # pocket A's goals are candidates too, but farther along their paths than B's
    a_side = cand.frontier & (cand.cells % 30 > 10)
    assert a_side.any() and cand.distance[a_side].min() > 0.9 > 0.5 > cand.distance[j]


def test_an_empty_candidate_set_ends_the_run():
    """A corridor 2 cells wide: a robot of clearance 1 fits at no other stop."""
    truth = np.ones((20, 40), bool)
    truth[9:11, 2:38] = False
    truth[9:12, 2:5] = False  # a 3 x 3 room: its centre is the only cell the robot's disk fits
    grid = Grid(truth.shape, 0.05)
    for m in (Method("frontier", "frontier"), Method("ogm", "ogm_info")):
        robot = Robot(beams=60, max_range_cells=8, sigma_cells=0.1, min_step_cells=2.0)  # no wall read as free
        run = explore(truth, grid, m, robot, stops=5, start=(10, 3))
        assert run.stopped == "no candidate" and len(run.records) == 1
        assert run.records[0]["coverage"] < 1


def test_bad_starts_and_settings_are_refused(office):
    truth, grid = office
    with pytest.raises(CandidateError, match="off the grid"):
        explore(truth, grid, Method("f", "frontier"), stops=2, start=(70, 3))
    with pytest.raises(CandidateError, match="inside an obstacle"):
        explore(truth, grid, Method("f", "frontier"), stops=2, start=(0, 0))
    with pytest.raises(ValueError, match="prior is given with rule 'sample_info'"):
        Method("x", "sample_info")
    with pytest.raises(ValueError, match="prior is given with rule 'sample_info' or 'sample_coverage'"):
        Method("x", "sample_coverage")
    with pytest.raises(ValueError, match="rule must be one of"):
        Method("x", "nearest")
    with pytest.raises(ValueError, match="threshold"):
        Robot(threshold=0.0)
    with pytest.raises(ValueError, match="stops"):
        explore(truth, grid, Method("f", "frontier"), stops=0)


def test_path_to_reads_the_first_stop_at_the_level():
    recs = [
        {"path_length": 0.0, "coverage": 0.2},
        {"path_length": 1.5, "coverage": 0.9},
        {"path_length": 3.0, "coverage": 1},
    ]
    assert path_to(recs, "coverage", 0.9) == 1.5
    assert path_to(recs, "coverage", 1.1) == np.inf


def test_ogm_mapper_adds_scans_as_one_batch_would(office):
    from ogm_ppl.datasets.simulate import simulate_scans
    from ogm_ppl.inference import evidence_grid_from_scans
    from ogm_ppl.models import delta_by_name

    truth, grid = office
    poses = np.array([[1.0, 1.0, 0.0], [2.0, 1.5, 0.0], [1.5, 2.2, 0.0]])
    scans = simulate_scans(grid, truth, poses, np.linspace(0, 6, 40), 0.6, 1.0, 0)
    m = OGMMapper(grid)
    for i in range(3):
        m.add_scans(_one(scans, i))
    ref = evidence_grid_from_scans(grid, scans, delta_by_name("haehnel"))
    np.testing.assert_allclose(m.log_odds, ref.log_odds.numpy(), atol=1e-12)
    np.testing.assert_array_equal(m.observed, ref.observed.numpy())


def _one(scans, i):
    from ogm_ppl.scans import Scans

    angles = scans.angles if scans.angles.ndim == 1 else scans.angles[i]
    return Scans(scans.poses[i : i + 1], angles, scans.ranges[i : i + 1], scans.max_range)


def test_rebuild_mapper_continues_its_chain_and_samples_the_model_of_all_scans(office):
    from ogm_ppl.datasets.simulate import simulate_scans

    truth, grid = office
    scans = simulate_scans(
        grid, truth, np.array([[1.0, 1.0, 0.0], [2.0, 1.5, 0.0]]), np.linspace(0, 6, 40), 0.6, 1.0, 0
    )
    torch.manual_seed(0)
    m = RebuildMapper(grid, GaussianRange(1.0), IndependentPrior(0.5, grid.num_cells), sweeps=2)
    m.add_scans(_one(scans, 0))
    m.add_scans(_one(scans, 1))
    assert m.kernel.model.rays.num_rays == 80
    s = m.samples(5)
    assert s.shape == (5, grid.num_cells) and s.dtype == torch.uint8
    np.testing.assert_allclose(m.marginals.numpy(), s.double().mean(0).numpy())
    with pytest.raises(ValueError, match="another maximum range"):
        m.add_scans(simulate_scans(grid, truth, np.array([[1.0, 1.0, 0.0]]), np.linspace(0, 6, 40), 0.5, 1.0, 0))


def test_default_mapper_is_the_online_map_for_single_cell_priors_and_the_rebuild_for_tile_tables(office):
    from ogm_ppl.datasets.simulate import simulate_scans
    from ogm_ppl.exploration.active import OnlineMapper, default_mapper
    from ogm_ppl.priors.named import prior_by_name

    truth, grid = office
    sensor = GaussianRange(1.0)
    ind = default_mapper(grid, sensor, prior_by_name("independent", grid.shape), ROBOT, 3)
    tab = default_mapper(grid, sensor, prior_by_name("patch3:houseexpo", grid.shape), ROBOT, 3)
    assert isinstance(ind, OnlineMapper) and isinstance(tab, RebuildMapper)
    # the online map and the rebuilt model hold the same model of the scans so far
    scans = simulate_scans(
        grid, truth, np.array([[1.0, 1.0, 0.0], [2.0, 1.5, 0.0]]), np.linspace(0, 6, 40), 0.6, 1.0, 0
    )
    ref = RebuildMapper(grid, sensor, prior_by_name("independent", grid.shape), sweeps=1)
    for i in range(2):
        ind.add_scans(_one(scans, i))
        ref.add_scans(_one(scans, i))
    a, b = ind.map.model, ref.kernel.model
    assert a.rays.num_rays == b.rays.num_rays == 80
    np.testing.assert_array_equal(a.known_free.numpy(), b.known_free.numpy())
    s = ind.samples(4)
    np.testing.assert_allclose(ind.marginals.numpy(), s.double().mean(0).numpy())  # the mean of what it returned


def test_a_path_budget_ends_the_run(office):
    truth, grid = office
    robot = Robot(beams=60, max_range_cells=12, sigma_cells=1.0, max_path_length=1.0)
    run = explore(truth, grid, Method("ogm", "ogm_info"), robot, stops=30, seed=0)
    d = [r["path_length"] for r in run.records]
    assert run.stopped == "path length" and d[-1] >= 1.0 > d[-2]


@pytest.mark.parametrize("per_metre", [False, True])
def test_the_coverage_rule_picks_the_most_expected_new_cells(per_metre):
    """Rule sample_coverage on the scene of the frontier test: the chosen
    stop has the largest expected count of unobserved cells its scan crosses (per metre driven plus d0).
    Samples: the observed cells thresholded, the unobserved ones occupied with probability 0.3."""
    from ogm_ppl.exploration.information import candidate_rays, expected_new_cells

    grid, q, observed = _frontier_scene()
    robot = Robot(clearance_cells=1.0, min_step_cells=2.0, max_candidates=10_000, threshold=0.5)
    planner = PathPlanner(grid, robot.clearance_cells, robot.risk_weight)
    u = torch.rand((16, q.size), generator=torch.Generator().manual_seed(0), dtype=torch.float64)
    samples = torch.where(torch.from_numpy(observed), torch.from_numpy(q) > 0.5, u < 0.3).to(torch.uint8)
    angles = np.linspace(0, 2 * np.pi, 48, endpoint=False)
    m = Method("cov", "sample_coverage", prior="independent", per_metre=per_metre)
    j, cand, info = _choose(
        m, robot, planner, grid, 15 * 30 + 4, q, q, samples, observed, [], GaussianRange(1.0), angles[::4], 0.6,
        0.6, scan_angles=angles,
    )  # fmt: skip
    assert j is not None and len(cand) > 10
    gain = expected_new_cells(grid, samples, candidate_rays(grid, cand.poses, angles, 0.6), observed).numpy()
    score = gain / (cand.distance + 0.6) if per_metre else gain
    assert score[j] == score.max() and info["gain_cells"] == gain[j] > 0
