"""One range convention for simulator, ray casting and sensor model (ogm_ppl.raycast docstring).

A beam returns where it enters the first occupied cell; a metric range becomes the kappa of the cell
whose entry is nearest to it; the sensor centres p(z | f) on f (in the continuous kappa t + 1/2 of
ogm_ppl.sensors). So simulated readings of a wall at f average the mean of the model's p(z | f), not half a
cell short of it.
"""

import math

import numpy as np
import pytest
import torch

from ogm_ppl import GaussianRange, Grid, Scans, raycast
from ogm_ppl.datasets import simulate_scans


def _model_mean(sigma: float, f: float, F: float) -> float:
    """Mean of the model's p(z | f) over hits (GaussianRange, continuous kappa), by quadrature."""
    z = torch.linspace(-0.5, F + 0.5, 200_001, dtype=torch.float64)
    p = GaussianRange(sigma).log_prob(z, f, F).exp()
    return float((z * p).sum() / p.sum())


def _simulate(grid, truth, pose, angle, n, sigma, max_range, seed=0):
    """Readings of one beam direction, ray cast; the model's coordinates of each reading and of f."""
    scans = simulate_scans(grid, truth, np.array([pose]), np.full(n, angle), max_range, sigma, seed=seed)
    rays = raycast(grid, scans)
    assert (~rays.is_max).all()
    occ = truth.ravel()[rays.cells[rays.offsets[0] : rays.offsets[1]]]
    f = int(np.flatnonzero(occ)[0])  # the same ray for every beam
    z_c = rays.range_cells + 0.5  # continuous kappa of the readings, as OccupancyModel evaluates them
    f_c = float(rays.t_enter[rays.offsets[0] + f]) + 0.5  # continuous kappa of the first occupied cell
    return rays, f, z_c, f_c


@pytest.mark.parametrize("sigma", [0.01, 1.0, 3.0])
def test_1d_simulated_readings_average_the_model_mean(sigma):
    K, wall = 80, 40
    grid = Grid.line(K)
    truth = np.zeros(K, dtype=bool)
    truth[wall:] = True
    n = 40_000
    rays, f, z_c, f_c = _simulate(grid, truth, (0.5, 0.0, 0.0), 0.0, n, sigma, max_range=K - 1.0)
    assert f == wall and f_c == wall  # in 1D the continuous kappa of the wall is the wall's index
    # tolerance 0.05 cells; the Monte-Carlo standard error is sigma / sqrt(n) <= 0.015
    assert abs(z_c.mean() - _model_mean(sigma, f_c, K - 1.0)) < 0.05
    # integer kappa (traditional OGM): the nearest entry, so symmetric noise averages f as well
    assert abs(rays.z.mean() - f) < 0.05
    if sigma < 0.1:
        assert (rays.z == f).all()  # near-noiseless readings land on the wall's cell, never on f - 1


@pytest.mark.parametrize("angle", [0.0, 0.3, math.pi / 4, 1.1, 2.0, -2.6])
def test_2d_simulated_readings_average_the_model_mean(angle):
    grid = Grid((161, 161), resolution=0.1, origin=(-8.05, -8.05))
    # a thick circular wall around the sensor: every beam meets it at about 6 m
    yy, xx = np.mgrid[0:161, 0:161]
    truth = np.hypot(xx - 80, yy - 80) >= 60
    n, sigma, max_range = 60_000, 2.0, 7.9
    _, _, z_c, f_c = _simulate(grid, truth, (0.013, -0.021, 0.0), angle, n, sigma, max_range)
    # standard error sigma / sqrt(n) = 0.008 cells
    assert abs(z_c.mean() - _model_mean(sigma, f_c, max_range / 0.1)) < 0.05
    rays0, f0, _, _ = _simulate(grid, truth, (0.013, -0.021, 0.0), angle, 200, 1e-4, max_range)
    assert (rays0.z == f0).all()  # noise-free: the reading's kappa is the wall's


def test_reading_exactly_at_a_cell_centre_goes_to_the_nearer_cell():
    # the thesis's integer toy readings from a robot in the middle of cell 0 are the kappa values
    rays = raycast(Grid.line(12), Scans.one_d([3.0, 7.5, 7.49, 8.0], max_range=11.0))
    assert rays.z.tolist() == [3, 8, 8, 8]


def test_a_wall_in_the_last_half_cell_of_the_range_can_be_seen():
    """A cell entered at t in (L - 1/2, L) is in the ray (entered before max range L) and the simulator makes
    hits off it; the model must give them a positive likelihood (its continuous kappa t + 1/2 lies in
    (F, F + 1/2], which once read as "no occupied cell": -inf for every such hit, 98 of 55,440 rays of a
    Table 6.4 dataset, and Gibbs then invented walls in front of the true one to explain them)."""
    from ogm_ppl import OccupancyModel
    from ogm_ppl.priors import IndependentPrior

    grid = Grid((121, 121), resolution=0.1, origin=(-6.05, -6.05))
    yy, xx = np.mgrid[0:121, 0:121]
    truth = np.hypot(xx - 60, yy - 60) >= 49.8  # a circular wall about 4.98 m out
    angles = np.linspace(-np.pi, np.pi, 720, endpoint=False)
    scans = simulate_scans(grid, truth, np.array([[0.0, 0.0, 0.0]]), angles, max_range=5.0, sigma_cells=1.0, seed=1)
    rays = raycast(grid, scans)
    model = OccupancyModel(grid, rays, GaussianRange(1.0), IndependentPrior(0.3, grid.num_cells))
    f = model.first_hits(torch.from_numpy(truth.ravel().astype(np.float64))[None])[0]
    R = torch.arange(rays.num_rays)
    t_f = torch.from_numpy(rays.t_enter[rays.offsets[:-1] + np.minimum(f.numpy(), rays.lengths - 1)]).double()
    last_half = (f < torch.from_numpy(rays.lengths)) & (t_f > 49.5)
    assert last_half.sum() > 20 and (~torch.from_numpy(rays.is_max) & last_half).sum() > 5  # the case occurs
    assert torch.isfinite(model.loglik_table[R, f]).all()
    # and the sensor's own definition: f in (F, F + 1/2] is a hit, beyond F + 1/2 is "none"
    s = GaussianRange(1.0)
    assert math.isfinite(float(s.log_prob(49.8, 50.3, 50.0))) and s.log_prob(49.8, 51.0, 50.0) == -math.inf
