"""The simulator's conventions (ogm_ppl.datasets.simulate): the cell holding a sensor is free."""

import numpy as np
import pytest
import torch

from ogm_ppl import GaussianRange, Grid, OccupancyModel, raycast
from ogm_ppl.datasets.simulate import simulate_scans
from ogm_ppl.priors import IndependentPrior


def test_a_sensor_inside_a_wall_is_refused_by_the_simulator_and_the_model():
    # one convention: the cell holding a sensor is free (the model pins it); both simulators refuse it
    grid = Grid((10, 10), resolution=1.0)
    truth = np.zeros((10, 10), bool)
    truth[5, 5] = True
    with pytest.raises(ValueError, match=r"pose 1 \(5.5, 5.5\) lies in occupied cell \(row 5, col 5\)"):
        simulate_scans(grid, truth, [[2.5, 2.5, 0.0], [5.5, 5.5, 0.0]], np.zeros(3), 5.0, 0.5)
    scans = simulate_scans(grid, truth, [[2.5, 2.5, 0.0]], np.zeros(3), 5.0, 0.5)
    model = OccupancyModel(grid, raycast(grid, scans), GaussianRange(0.5), IndependentPrior(0.3, 100))
    m = torch.zeros(100, dtype=torch.float64)
    m[2 * 10 + 2] = 1.0
    with pytest.raises(ValueError, match="pinned free"):
        model.simulate_readings(m)
