"""Ray-casting behaviour the main tests leave open (found by `make mutate`, issue 15): the ray
count, the entries past the grid edge against the reference crossings, the capacity bound, identity
semantics of ``Rays`` and the immutable transposed index, and which pose an error names."""

import dataclasses
import math

import numpy as np
import pytest

from ogm_ppl import Grid, Scans, raycast
from ogm_ppl.raycast import ray_inputs
from ogm_ppl.reference import _crossings


def _scans(n_rays: int = 7, max_range: float = 40.0) -> tuple[Grid, Scans]:
    rng = np.random.default_rng(11)
    grid = Grid((9, 13), resolution=1.0)
    poses = [[2.3, 5.7, 0.0], [10.6, 1.2, 2.0]]
    angles = rng.uniform(-math.pi, math.pi, n_rays)
    ranges = rng.uniform(0.5, max_range * 1.2, (2, n_rays))
    return grid, Scans(poses, angles, ranges, max_range=max_range, over_range="max")


def test_num_rays_and_default_reading_index():
    grid, scans = _scans()
    rays = raycast(grid, scans)
    assert rays.num_rays == 14 == len(rays.z)
    np.testing.assert_array_equal(rays.reading, np.arange(14))


def test_entries_beyond_edge_match_the_reference_crossings():
    """Past the grid edge each ray's entry distances are the crossings of an unbounded grid, from the
    ray's own start ``(u0, v0)`` (here ``u0 != v0`` everywhere), up to max range."""
    grid, scans = _scans()
    rays = raycast(grid, scans)
    ri = ray_inputs(grid, scans)
    off, t = rays.entries_beyond_edge(np.arange(rays.num_rays))
    assert off[0] == 0 and len(off) == rays.num_rays + 1
    cut = 0
    for r in range(rays.num_rays):
        u0, v0, du, dv, L = ri.u0[r], ri.v0[r], ri.du[r], ri.dv[r], ri.length[r]
        assert u0 != v0
        ts = [0.0, *sorted(_crossings(u0, du, L) + _crossings(v0, dv, L))]
        n_in = rays.offsets[r + 1] - rays.offsets[r]
        np.testing.assert_allclose(t[off[r] : off[r + 1]], ts[n_in:], rtol=1e-5, atol=1e-5)
        cut += len(ts) > n_in
    assert cut >= 5  # most rays leave the grid before max range


@pytest.mark.parametrize("angle", [0.0, 0.3, math.pi / 4, 1.2, math.pi / 2, 2.5])
def test_capacity_bounds_every_ray(angle):
    """``RayInputs.capacity()`` bounds the cells of every ray and every reading's kappa, on an unbounded
    grid too (``range_len``), for long rays at any angle."""
    grid = Grid((80, 80), resolution=1.0)
    scans = Scans([[40.5, 40.5, angle]], [0.0, 0.1, -0.1], [[35.0, 39.0, 38.0]], max_range=38.0,
                  over_range="max")
    rays = raycast(grid, scans)
    cap = ray_inputs(grid, scans).capacity()
    assert cap >= int(np.diff(rays.offsets).max())
    assert cap >= int(rays.range_len.max()) and cap >= int(rays.z.max())


def test_rays_compare_by_identity():
    """``Rays`` hold arrays: equality is identity (two casts of the same scans are different objects)
    and they can be used as dictionary keys."""
    grid, scans = _scans(3)
    a, b = raycast(grid, scans), raycast(grid, scans)
    assert a == a and a != b
    assert len({a: 1, b: 2}) == 2


def test_transposed_index_is_immutable():
    grid, scans = _scans(3)
    idx = raycast(grid, scans).by_cell
    with pytest.raises(dataclasses.FrozenInstanceError):
        idx.offsets = idx.offsets.copy()


def test_error_names_the_first_pose_outside_the_grid():
    grid = Grid((5, 5), resolution=1.0)
    scans = Scans([[1.0, 1.0, 0.0], [9.0, 1.0, 0.0], [1.0, 9.0, 0.0]], [0.0], [[1.0]] * 3, max_range=3.0)
    with pytest.raises(ValueError, match=r"poses\[1\]"):
        raycast(grid, scans)
