"""One range convention for simulator, ray casting and sensor model (ogm_ppl.raycast docstring).

A beam returns where it enters the first occupied cell; a metric range becomes the kappa of the cell
whose entry is nearest to it; the sensor centres p(z | f) on f (in the continuous kappa t + 1/2 of
ogm_ppl.sensors). So simulated readings of a wall at f average the mean of the model's p(z | f) (Issue: they sat half a cell short, -0.51 cells).
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
