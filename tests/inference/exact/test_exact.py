import itertools
import math
import time

import numpy as np
import pytest
import torch

from ogm_ppl import GaussianRange, Grid, OccupancyModel, PatternMatch, Scans, raycast
from ogm_ppl.datasets import THESIS_TOY_READINGS, toy_1d
from ogm_ppl.inference.exact import brute_force, pose_constrained_1d, pyro_enumeration
from ogm_ppl.priors import DataDriven1DPrior, IndependentPrior


def model_1d(K, readings, sensor=None, prior=None):
    toy = toy_1d(num_cells=K + 1, wall=1, readings=readings)  # cell 0 holds the robot: K latent cells
    rays = raycast(toy.grid, toy.scans)
    prior = prior if prior is not None else IndependentPrior(0.5, K + 1)
    return OccupancyModel(toy.grid, rays, sensor or GaussianRange(3.0), prior)


def random_1d(seed):
    rng = np.random.default_rng(seed)
    K = int(rng.integers(2, 17))
    n = int(rng.integers(1, 9))
    readings = np.clip(np.rint(rng.normal(rng.integers(1, K + 1), 2.0, n)), 0, K)
    lam = torch.as_tensor(rng.uniform(0.05, 0.95, K + 1))
    sensor = GaussianRange(float(rng.uniform(0.5, 4.0))) if seed % 3 else PatternMatch(0.7)
    return model_1d(K, readings, sensor, IndependentPrior(lam))


def assert_no_nan(*tensors):
    for t in tensors:
        assert not torch.isnan(torch.as_tensor(t)).any()


@pytest.mark.parametrize("seed", range(24))
def test_brute_force_equals_pose_constrained(seed):
    model = random_1d(seed)
    bf, pc = brute_force(model), pose_constrained_1d(model)
    K = model.num_cells
    torch.testing.assert_close(bf.marginals, pc.marginals, rtol=0, atol=1e-10)
    torch.testing.assert_close(bf.first_hit(0), pc.first_hit(0), rtol=0, atol=1e-10)
    torch.testing.assert_close(bf.pair_joint(), pc.pair_joint(torch.arange(K)), rtol=0, atol=1e-10)
    torch.testing.assert_close(bf.mutual_information(), pc.mutual_information(torch.arange(K)), rtol=0, atol=1e-9)
    path = [1, K - 1] if K > 2 else [1]
    assert bf.prob_free(path) == pytest.approx(pc.prob_free(path), abs=1e-10)
    assert bf.log_evidence == pytest.approx(pc.log_evidence, abs=1e-9)
    assert_no_nan(bf.marginals, pc.marginals, bf.first_hit(0), pc.mutual_information())


@pytest.mark.parametrize("seed", range(8))
def test_data_driven_prior_matches_brute_force(seed):
    rng = np.random.default_rng(100 + seed)
    K = int(rng.integers(3, 15))
    readings = np.clip(np.rint(rng.normal(K / 2, 2.0, int(rng.integers(1, 7)))), 0, K)
    model = model_1d(K, readings, prior=DataDriven1DPrior(K + 1, start=1))
    bf, pc = brute_force(model), pose_constrained_1d(model)
    torch.testing.assert_close(bf.marginals, pc.marginals, rtol=0, atol=1e-10)
    torch.testing.assert_close(bf.first_hit(0), pc.first_hit(0), rtol=0, atol=1e-10)
    torch.testing.assert_close(bf.mutual_information(), pc.mutual_information(torch.arange(K + 1)), rtol=0, atol=1e-9)
    assert bf.prob_free([2, 3]) == pytest.approx(pc.prob_free([2, 3]), abs=1e-10)


def test_thesis_toy_statistics():
    model = model_1d(20, THESIS_TOY_READINGS)
    pc = pose_constrained_1d(model)
    pf = pc.first_hit()
    assert pf.sum().item() == pytest.approx(1.0, abs=1e-12)
    assert int(pf.argmax()) == 7  # uniform prior: f = 7 most likely, not 8 (Section 4.2.3)
    dd = pose_constrained_1d(model_1d(20, THESIS_TOY_READINGS, prior=DataDriven1DPrior(21, 1)))
    assert int(dd.first_hit().argmax()) == 8  # data-driven prior: f = 8 (Fig. 5.4)
    # uniform prior: cells far behind the wall stay at the prior; data-driven: occupied
    assert pc.marginals[20].item() == pytest.approx(0.5, abs=1e-6)
    assert dd.marginals[20].item() == pytest.approx(1.0, abs=1e-6)
    # P(cells 1..7 free) = P(f >= 8): exact, and not the cell-independence product
    path = list(range(1, 8))
    assert pc.prob_free(path) == pytest.approx(pf[8:].sum().item(), abs=1e-12)
    assert abs(pc.prob_free(path) - pc.prob_free_independent(path)) > 1e-3


def tiny_2d(prior_kind="independent"):
    grid = Grid((3, 3), resolution=1.0)
    scans = Scans(
        [[0.5, 0.5, 0.0], [0.5, 0.5, math.pi / 2], [2.5, 2.5, math.pi], [2.5, 1.5, math.pi]],
        [0.0],
        [[1.2], [2.0], [1.5], [0.9]],
        max_range=2.5,
    )
    rays = raycast(grid, scans)
    prior = IndependentPrior(torch.linspace(0.2, 0.7, 9)) if prior_kind == "independent" else None
    return OccupancyModel(grid, rays, GaussianRange(0.8), prior)


@pytest.mark.parametrize("which", ["1d", "1d_data_driven", "2d"])
def test_pyro_enumeration_agrees_with_brute_force(which):
    if which == "1d":
        model = model_1d(10, [3.0, 5.0, 4.0])
    elif which == "1d_data_driven":
        model = model_1d(9, [3.0, 5.0], prior=DataDriven1DPrior(10, 1))
    else:
        model = tiny_2d()
    import pyro

    pyro.clear_param_store()
    mine = pyro.param("users_own_param", torch.ones(3)).detach().clone()
    got = pyro_enumeration(model)
    torch.testing.assert_close(got, brute_force(model).marginals, rtol=0, atol=1e-6)
    assert list(pyro.get_param_store().keys()) == ["users_own_param"]  # the caller's store is left alone
    torch.testing.assert_close(pyro.param("users_own_param").detach(), mine)
    pyro.clear_param_store()


def test_mutual_information_properties():
    model = tiny_2d()
    bf = brute_force(model)
    mi = bf.mutual_information()
    assert torch.equal(mi, mi.T) and (mi >= 0).all()
    # cells that no chain of readings couples are independent: rays are linked when they share a
    # latent cell; cells in different groups (or on no ray) have zero MI
    r = model.rays
    latent = set(model.latent.tolist())
    rays = [set(r.ray(i).tolist()) & latent for i in range(r.num_rays)]
    group = list(range(len(rays)))
    for a, b in itertools.combinations(range(len(rays)), 2):
        if rays[a] & rays[b]:
            ga, gb = group[a], group[b]
            group = [ga if g == gb else g for g in group]
    cell_group = {c: group[i] for i, s in enumerate(rays) for c in s}
    checked = 0
    for i, j in itertools.combinations(range(9), 2):
        if cell_group.get(i, -1 - i) != cell_group.get(j, -1 - j):
            assert mi[i, j].item() == pytest.approx(0.0, abs=1e-12), (i, j)
            checked += 1
    assert checked > 5
    # cells on the same ray are coupled
    cells = r.ray(0)
    assert mi[cells[1], cells[2]] > 1e-4


def test_log_joint_batch_and_pyro_trace():
    import pyro.poutine as poutine

    model = tiny_2d()
    maps = brute_force(model)
    g = torch.Generator().manual_seed(0)
    batch = (torch.rand(17, 9, generator=g) < 0.5).double()
    batch[:, model.known_free] = 0
    lj = model.log_joint(batch)
    assert lj.shape == (17,)
    for b in range(17):
        assert lj[b].item() == pytest.approx(model.log_joint(batch[b]).item(), abs=1e-12)
    tr = poutine.trace(poutine.condition(model.model, data={"m": batch[3]})).get_trace()
    assert tr.log_prob_sum().item() == pytest.approx(lj[3].item(), abs=1e-10)
    assert maps.num_maps == 2 ** len(model.latent)


def test_refuses_large_problems_quickly():
    model = model_1d(30, [5.0])
    t = time.perf_counter()
    with pytest.raises(ValueError, match="max_cells = 24"):
        brute_force(model)
    assert time.perf_counter() - t < 1.0
    with pytest.raises(ValueError, match="max_cells"):
        pyro_enumeration(model)


def test_zero_mass_and_empty_inputs():
    # a perfect pattern-matching sensor cannot explain two different readings: no map has mass
    model = model_1d(6, [2.0, 4.0], sensor=PatternMatch(1.0))
    with pytest.raises(ValueError, match="zero posterior mass"):
        brute_force(model)
    with pytest.raises(ValueError, match="zero posterior mass"):
        pose_constrained_1d(model)
    grid = Grid.line(5)
    empty = raycast(grid, Scans(np.zeros((0, 3)), np.zeros(0), np.zeros((0, 0)), max_range=3.0))
    with pytest.raises(ValueError, match="empty"):
        OccupancyModel(grid, empty, GaussianRange(1.0), IndependentPrior(0.5, 5))


def test_pose_constrained_rejects_moving_robot():
    grid = Grid.line(10)
    scans = Scans([[0.5, 0.0, 0.0], [2.5, 0.0, 0.0]], [0.0], [[3.0], [3.0]], max_range=6.0)
    model = OccupancyModel(grid, raycast(grid, scans), GaussianRange(1.0), IndependentPrior(0.5, 10))
    with pytest.raises(ValueError, match="same ray"):
        pose_constrained_1d(model)


def test_pose_constrained_scales():
    model = model_1d(1000, THESIS_TOY_READINGS)
    t = time.perf_counter()
    pc = pose_constrained_1d(model)
    m = pc.marginals
    assert time.perf_counter() - t < 1.0
    assert m.shape == (1001,) and not torch.isnan(m).any()
    assert m[500].item() == pytest.approx(0.5, abs=1e-9)


@pytest.mark.parametrize("direction", [1, -1])
def test_default_cell_order_agrees_between_solvers(direction):
    # One order everywhere: with no `cells` argument every posterior returns K x K matrices in cell
    # order (a robot looking in -x visits the cells in reverse; ray order differed by up to 0.69)
    K = 9
    grid = Grid.line(K)
    position = 0.5 if direction == 1 else K - 0.5
    scans = Scans.one_d([3.5, 4.5, 2.5, 6.5], max_range=K - 1.0, position=position, direction=direction)
    model = OccupancyModel(grid, raycast(grid, scans), GaussianRange(1.5), IndependentPrior(0.4, K))
    bf, pc = brute_force(model), pose_constrained_1d(model)
    assert pc.pair_joint().shape == (K, K)
    torch.testing.assert_close(bf.pair_joint(), pc.pair_joint(), rtol=0, atol=1e-10)
    torch.testing.assert_close(bf.mutual_information(), pc.mutual_information(), rtol=0, atol=1e-9)
    torch.testing.assert_close(bf.marginals, pc.marginals, rtol=0, atol=1e-10)
