import math

import numpy as np
import pytest
import torch

from ogm_ppl import GaussianRange, Grid, OccupancyModel, Scans, raycast
from ogm_ppl.inference._cell_kernels import first_hits
from ogm_ppl.priors import IndependentPrior


def test_first_hits_agree_with_compiled_kernel_and_a_loop():
    rng = np.random.default_rng(0)
    grid = Grid((12, 15), resolution=1.0)
    scans = Scans(np.c_[rng.uniform(0, 15, 4), rng.uniform(0, 12, 4), rng.uniform(-3, 3, 4)],
                  rng.uniform(-3, 3, 30), rng.uniform(0, 9, (4, 30)), max_range=8.0, over_range="max")  # fmt: skip
    rays = raycast(grid, scans)
    model = OccupancyModel(grid, rays, GaussianRange(1.0), IndependentPrior(0.3, grid.num_cells))
    maps = (torch.rand(5, grid.num_cells, generator=torch.Generator().manual_seed(1)) < 0.2).double()
    got = model.first_hits(maps)
    for b in range(5):
        m = maps[b].numpy().astype(np.uint8)
        np.testing.assert_array_equal(got[b].numpy(), first_hits(m, rays.offsets, rays.cells))
        for r in range(rays.num_rays):
            occ = [k for k, c in enumerate(rays.ray(r)) if m[c]]
            assert got[b, r] == (occ[0] if occ else rays.lengths[r])


def test_likelihood_table_and_out_of_grid_hits():
    grid = Grid.line(6)
    scans = Scans.one_d([2.0, 9.0, 20.0], max_range=20.0)  # in grid, past the edge, max range
    rays = raycast(grid, scans)
    assert rays.endpoint_in_grid.tolist() == [True, False, False] and rays.is_max.tolist() == [False, False, True]
    s = GaussianRange(1.5)
    model = OccupancyModel(grid, rays, s, IndependentPrior(0.5, 6))
    free = torch.zeros(6)
    # all cells free: the max-range reading is certain, the hit past the edge is explained by an
    # obstacle outside the grid at the reading, the in-grid hit is impossible
    ll = model.loglik_table
    assert ll[0, 6] == -math.inf
    assert ll[1, 6].item() == pytest.approx(-math.log(1.5 * math.sqrt(2 * math.pi)))
    assert ll[2, 6].item() == 0.0
    wall = torch.zeros(6)
    wall[4] = 1.0
    expected = s.log_prob(torch.tensor(2.0), 4, 5) + s.log_prob(torch.tensor(9.0), 4, 9) + \
        s.log_prob(torch.tensor(0.0), 4, 5, is_max=True)  # fmt: skip
    assert model.log_likelihood(wall).item() == pytest.approx(expected.item(), abs=1e-12)
    assert model.log_likelihood(free).item() == -math.inf
    assert model.known_free.tolist() == [True] + [False] * 5


def test_model_validation():
    grid = Grid.line(6)
    rays = raycast(grid, Scans.one_d([2.0], max_range=5.0))
    with pytest.raises(ValueError, match="prior has 4 cells"):
        OccupancyModel(grid, rays, GaussianRange(1.0), IndependentPrior(0.5, 4))
    with pytest.raises(ValueError, match="different grid"):
        OccupancyModel(Grid.line(7), rays, GaussianRange(1.0), IndependentPrior(0.5, 7))
    with pytest.raises(ValueError, match="known_free"):
        OccupancyModel(grid, rays, GaussianRange(1.0), IndependentPrior(0.5, 6), known_free=[9])
    m = OccupancyModel(grid, rays, GaussianRange(1.0), IndependentPrior(0.5, 6), known_free=None)
    assert len(m.latent) == 6
