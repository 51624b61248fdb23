import dataclasses
import math

import numpy as np
import pytest
import torch

from ogm_ppl import Grid, Scans, raycast
from ogm_ppl.datasets import THESIS_TOY_READINGS, toy_1d
from ogm_ppl.inference import evidence_grid, evidence_grid_from_scans
from ogm_ppl.inference.log_odds import OCTOMAP_CLAMP, delta_table_for
from ogm_ppl.models import (
    PN,
    BorensteinKoren,
    Elfes,
    MarshallBarfoot,
    Moravec,
    Stachniss,
    delta_by_name,
)
from ogm_ppl.reference import evidence_grid_numpy, evidence_grid_reference

L4 = math.log(4.0)


def random_problem(seed, S=6, B=180, shape=(37, 45), res=0.1):
    rng = np.random.default_rng(seed)
    grid = Grid(shape, resolution=res, origin=(-1.0, 0.5))
    xmin, xmax, ymin, ymax = grid.extent
    poses = np.c_[rng.uniform(xmin, xmax, S), rng.uniform(ymin, ymax, S), rng.uniform(-np.pi, np.pi, S)]
    angles = rng.uniform(-np.pi, np.pi, (S, B))
    ranges = rng.uniform(0, 3.3, (S, B))
    return grid, Scans(poses, angles, ranges, max_range=3.0, over_range="max")


@pytest.mark.parametrize("seed", range(5))
def test_haehnel_equals_plain_per_ray_reference(seed):
    grid, scans = random_problem(seed)
    fast = evidence_grid(raycast(grid, scans), Moravec.haehnel()).log_odds.numpy()
    ref = evidence_grid_reference(grid, scans, L4, -L4)
    np.testing.assert_allclose(fast, ref, rtol=0, atol=1e-12)
    np.testing.assert_allclose(evidence_grid_numpy(grid, scans, L4, -L4), ref, rtol=0, atol=1e-12)
    fused = evidence_grid_from_scans(grid, scans, Moravec.haehnel()).log_odds.numpy()
    np.testing.assert_allclose(fused, ref, rtol=0, atol=1e-12)


def test_prior_shifts_every_cell():
    grid, scans = random_problem(7)
    rays = raycast(grid, scans)
    a = evidence_grid(rays, Moravec.haehnel(), prior=0.234).log_odds.numpy()
    b = evidence_grid_reference(grid, scans, L4, -L4, prior=0.234)
    np.testing.assert_allclose(a, b, atol=1e-12)
    c = evidence_grid(rays, Moravec.haehnel()).log_odds.numpy()
    np.testing.assert_allclose(a - c, math.log(0.234 / 0.766), atol=1e-12)


FAMILIES = [
    Moravec.haehnel,
    lambda: BorensteinKoren(0.4),
    lambda: MarshallBarfoot(0.7, 2),
    lambda: Stachniss(0.5, -0.8, 7.0),
    lambda: Elfes(2.9627, -12.9047, max_kappa=40),
    lambda: PN(np.linspace(-2, 0.5, 21)),
]


@pytest.mark.parametrize("family", FAMILIES)
def test_all_paths_agree_for_every_family(family):
    grid, scans = random_problem(11, S=4, B=90)
    rays = raycast(grid, scans)
    d = family()
    compiled = evidence_grid(rays, d)
    torch_path = evidence_grid(rays, d, differentiable=True)
    fused = evidence_grid_from_scans(grid, scans, d)
    torch.testing.assert_close(torch_path.log_odds.detach(), compiled.log_odds, rtol=0, atol=1e-12)
    # the fused map is the sum of each cell's terms to two roundings; the compiled path adds its (at most 360)
    # terms in float one by one, each addition rounding by half an ulp of the running sum
    torch.testing.assert_close(fused.log_odds, compiled.log_odds, rtol=360 * 2.0**-53, atol=1e-12)
    assert torch.equal(compiled.observed, torch_path.observed)
    assert torch.equal(compiled.observed, fused.observed)
    # and against a direct, per-entry evaluation of the family's table
    table, max_col = delta_table_for(rays, d)
    table = table.detach()
    expected = np.zeros(grid.num_cells)
    for r in range(rays.num_rays):
        col = max_col if rays.is_max[r] else rays.z[r]
        for k, c in enumerate(rays.ray(r)):
            expected[c] += float(table[k, col])
    np.testing.assert_allclose(compiled.log_odds.numpy(), expected, atol=1e-12)


def test_clamping_is_sequential_per_update():
    grid, scans = random_problem(3, S=5, B=120)
    rays = raycast(grid, scans)
    d = Moravec(2.2, -0.9)
    got = evidence_grid(rays, d, clamp=OCTOMAP_CLAMP).log_odds.numpy()
    table, max_col = delta_table_for(rays, d)
    table = table.detach()
    ev = np.zeros(grid.num_cells)
    for r in range(rays.num_rays):
        col = max_col if rays.is_max[r] else rays.z[r]
        for k, c in enumerate(rays.ray(r)):
            if table[k, col] != 0:
                ev[c] = min(max(ev[c] + float(table[k, col]), -2.0), 3.5)
    np.testing.assert_allclose(got, ev, atol=1e-12)
    assert got.min() >= -2.0 and got.max() <= 3.5
    fused = evidence_grid_from_scans(grid, scans, d, clamp=OCTOMAP_CLAMP).log_odds.numpy()
    np.testing.assert_allclose(fused, ev, atol=1e-12)


def test_thesis_toy_by_hand():
    toy = toy_1d(num_cells=20, readings=THESIS_TOY_READINGS)
    m = evidence_grid(raycast(toy.grid, toy.scans), Moravec.haehnel())
    z = np.array(THESIS_TOY_READINGS)
    k = np.arange(20)[:, None]
    expected = (-L4 * (k < z) + L4 * (k == z)).sum(1)
    np.testing.assert_allclose(m.log_odds.numpy(), expected, atol=1e-12)
    assert m.observed.numpy().tolist() == [True] * 12 + [False] * 8  # nothing updates cells > 11


def test_observed_is_reached_for_haehnel_and_unknown_kept_apart():
    grid, scans = random_problem(5)
    rays = raycast(grid, scans)
    m = evidence_grid(rays, Moravec.haehnel())
    np.testing.assert_array_equal(m.observed.numpy(), rays.reached())
    img = m.image(unknown=np.nan)
    assert np.isnan(img).sum() == (~rays.reached()).sum()
    assert img.shape == grid.shape


def test_gradient_of_evidence():
    toy = toy_1d(num_cells=15, readings=[4.0, 6.0, 5.0])
    rays = raycast(toy.grid, toy.scans)
    target = torch.linspace(0.05, 0.95, 15)

    class Map(torch.nn.Module):
        def __init__(self, fam):
            super().__init__()
            self.fam = fam

        def forward(self):
            return evidence_grid(rays, self.fam, differentiable=True).probabilities

    for fam in (Moravec(0.9, -0.7), Elfes(2.0, -4.0), PN(torch.linspace(-1, 0.2, 5))):
        model = Map(fam)
        names = [n for n, _ in model.named_parameters()]
        params = tuple(p.detach().clone().requires_grad_(True) for p in model.parameters())

        def loss(*values):
            q = torch.func.functional_call(model, dict(zip(names, values)), ())
            return -(target * q.log() + (1 - target) * (1 - q).log()).sum()

        assert torch.autograd.gradcheck(loss, params)


def test_bad_arguments():
    grid, scans = random_problem(1, S=1, B=4)
    rays = raycast(grid, scans)
    with pytest.raises(ValueError, match="prior"):
        evidence_grid(rays, Moravec.haehnel(), prior=1.0)
    with pytest.raises(ValueError, match="clamp"):
        evidence_grid(rays, Moravec.haehnel(), clamp=(0.5, 3.0))
    with pytest.raises(ValueError, match="differentiable"):
        evidence_grid(rays, Moravec.haehnel(), clamp=OCTOMAP_CLAMP, differentiable=True)


def test_named_thesis_maps_run_on_the_simple_example():
    from ogm_ppl.datasets import simple_2d_example

    ex = simple_2d_example()
    rays = raycast(ex.grid, ex.scans)
    for name in ("haehnel", "moravec_thesis", "p21_thesis", "elfes_thesis"):
        p = evidence_grid(rays, delta_by_name(name)).probabilities
        assert torch.isfinite(p).all() and ((p >= 0) & (p <= 1)).all()


def test_nan_parameters_in_a_delta_are_refused():
    from ogm_ppl.inference import evidence_grid_from_scans

    grid = Grid.line(12)
    scans = Scans.one_d([3.0, 7.0], max_range=10.0)
    for delta in (Moravec(float("nan"), -1.0), PN([0.1, float("nan"), 0.2])):
        with pytest.raises(ValueError, match="non-finite update term"):
            evidence_grid(raycast(grid, scans), delta)
        with pytest.raises(ValueError, match="non-finite update term"):
            evidence_grid_from_scans(grid, scans, delta)


# ------------------------------------------------------- LogOddsMap is a value


def test_log_odds_map_is_immutable():
    """A ``LogOddsMap`` is a frozen value: its fields cannot be rebound after it is built."""
    rays = raycast(Grid.line(6), Scans.one_d([3.0], max_range=5.0))
    m = evidence_grid(rays, Moravec.haehnel())
    with pytest.raises(dataclasses.FrozenInstanceError):
        m.log_odds = torch.zeros(6)
    with pytest.raises(dataclasses.FrozenInstanceError):
        m.observed = torch.ones(6, dtype=torch.bool)


def test_fitted_term_far_from_its_range_warns_in_evidence_grid():
    # the one shared setting check: the shipped p21 was fitted for F = 75 cells; a 400-cell range
    # (20 m at 5 cm) warns from evidence_grid and from the fused path; 75 cells and haehnel do not
    import warnings

    from ogm_ppl.inference.variational import FittedSettingWarning
    from ogm_ppl.models import delta_by_name

    grid = Grid((40, 40), resolution=0.05)
    far = Scans([[1.0, 1.0, 0.0]], [0.0, 0.5], [[0.5, 0.6]], max_range=20.0)
    near = Scans([[1.0, 1.0, 0.0]], [0.0, 0.5], [[0.5, 0.6]], max_range=3.75)
    with pytest.warns(FittedSettingWarning, match=r"'p21'.*F = 400 cells.*evidence_grid"):
        evidence_grid(raycast(grid, far), delta_by_name("p21"))
    with pytest.warns(FittedSettingWarning, match="evidence_grid_from_scans"):
        evidence_grid_from_scans(grid, far, delta_by_name("p21"))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        evidence_grid(raycast(grid, near), delta_by_name("p21"))
        evidence_grid(raycast(grid, far), delta_by_name("haehnel"))
        evidence_grid(raycast(grid, far), delta_by_name("p21"), check_setting=False)


@pytest.mark.parametrize("family", [Moravec.haehnel, lambda: PN(np.linspace(-2, 0.5, 21))])
def test_the_fused_map_is_the_same_for_any_thread_count_and_the_exact_sum(family):
    """The rays split into 1, 2 or 3 parts walked side by side give the same map to the last bit (integer sums),
    and each cell is the correctly rounded sum of its float64 terms (``math.fsum``) to two roundings, tighter
    than a sequential float sum's ``n_k`` roundings."""
    grid, scans = random_problem(4, S=6, B=120)
    d = family()
    maps = [evidence_grid_from_scans(grid, scans, d, threads=t) for t in (1, 2, 3)]
    for m in maps[1:]:
        assert torch.equal(m.log_odds, maps[0].log_odds) and torch.equal(m.observed, maps[0].observed)
    rays = raycast(grid, scans)
    table, max_col = delta_table_for(rays, d)
    table = table.detach().numpy()
    terms: list[list[float]] = [[] for _ in range(grid.num_cells)]
    for r in range(rays.num_rays):
        col = max_col if rays.is_max[r] else rays.z[r]
        for k, c in enumerate(rays.ray(r)[: table.shape[0]]):
            terms[c].append(float(table[k, col]))
    exact = np.array([math.fsum(t) for t in terms])
    got = maps[0].log_odds.numpy()
    assert (np.abs(got - exact) <= 2 * np.spacing(np.abs(exact)) + 1e-300).all()
    with pytest.raises(ValueError, match="threads"):
        evidence_grid_from_scans(grid, scans, d, threads=0)
