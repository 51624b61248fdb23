"""Exact posteriors refuse the inputs they cannot handle (rays of different lengths, ...)."""

import pytest

from ogm_ppl import GaussianRange, Grid, OccupancyModel, Scans, raycast
from ogm_ppl.inference.exact import pose_constrained_1d
from ogm_ppl.priors import IndependentPrior


@pytest.mark.parametrize("positions", [(4.5, 0.5), (0.5, 4.5)], ids=["longer-ray-second", "longer-ray-first"])
def test_pose_constrained_rejects_rays_of_different_lengths(positions):
    """Two poses whose rays differ in length (the one from x = 4.5 is cut by the grid edge): refused
    with the "same ray" message whichever ray comes first, before any reshaping of the cell lists."""
    grid = Grid.line(10)
    scans = Scans([[x, 0.0, 0.0] for x in positions], [0.0], [[3.0], [3.0]], max_range=6.0)
    rays = raycast(grid, scans)
    assert sorted(rays.lengths.tolist()) == [6, 7]
    model = OccupancyModel(grid, rays, GaussianRange(1.0), IndependentPrior(0.5, 10))
    with pytest.raises(ValueError, match="same ray"):
        pose_constrained_1d(model)
