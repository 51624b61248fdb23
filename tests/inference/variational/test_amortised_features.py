"""The evidence features' update-term table: kept for small sizes (the same values as building it again), built
afresh for large ones, and the terms of rays cast apart equal those of the same rays cast together."""

import numpy as np
import torch

from ogm_ppl import Grid, Scans, raycast
from ogm_ppl.inference.variational import amortised_features as af
from ogm_ppl.models.occupancy import entry_table, range_to_kappa


def test_small_tables_are_kept_and_equal_a_fresh_table(monkeypatch):
    fresh = af._delta("p21").table(7, 9).to(torch.float64)
    kept = af._delta_table("p21", 7, 9)
    assert torch.equal(kept, fresh) and kept is af._delta_table("p21", 7, 9)
    monkeypatch.setattr(af, "_TABLE_CACHE_ENTRIES", 7 * 10 - 1)
    big = af._delta_table("p21", 7, 9)
    assert torch.equal(big, fresh) and big is not af._delta_table("p21", 7, 9)


def _terms(grid: Grid, scans: Scans):
    rays = raycast(grid, scans)
    F = torch.from_numpy(rays.max_range_cells()).to(torch.float64)
    z = torch.where(torch.from_numpy(rays.is_max.copy()), F, torch.from_numpy(rays.range_cells).double())
    return af.ray_terms(rays, range_to_kappa(entry_table(rays), z)[None], (z >= F)[None], "p21")


def test_ray_terms_of_scans_cast_apart_equal_those_cast_together():
    grid = Grid((20, 20), 0.1)
    poses = np.array([[1.05, 1.05, 0.0], [0.55, 1.45, 1.0]])
    angles = np.linspace(-1.5, 1.5, 5)
    ranges = np.array([[0.62, 0.9, 2.0, 1.1, 0.3], [1.2, 0.47, 0.8, 2.0, 0.66]])  # 2.0: max range
    both = Scans(poses, angles, ranges, max_range=2.0)
    together = _terms(grid, both)
    apart = [_terms(grid, Scans(poses[i : i + 1], angles, ranges[i : i + 1], max_range=2.0)) for i in range(2)]
    for k in range(3):
        assert torch.equal(together[k], torch.cat([a[k] for a in apart], 1))
