"""The pattern-field prior: the prior contract on enumerable grids (one and two scales, odd sizes), its
compiled cell and patch conditionals against ``log_prob`` differences, exact stationarity of the
brute-force posterior under cell and patch Gibbs, the symmetry orbits, and the shipped fits' loading."""

import itertools
import math

import numpy as np
import pytest
import torch

from ogm_ppl import GaussianRange, Grid, OccupancyModel, Scans, raycast
from ogm_ppl.inference._kernels.cell_sweep import prior_log_odds
from ogm_ppl.inference.exact import brute_force
from ogm_ppl.inference.mcmc.gibbs import CellGibbs, PatchGibbs
from ogm_ppl.priors import PatternFieldPrior, prior_by_name
from ogm_ppl.priors.compiled import PatternField, patch_prior_batch
from ogm_ppl.priors.pattern_field import (
    field_path,
    load_field,
    orbits_to_table,
    pooled_grid,
    symmetry_orbits,
    table_to_orbits,
)
from ogm_ppl.testing import PriorContract
from ogm_ppl.testing.kernels import enumerate_maps, sweep_matrix


def random_field(shape, w, two, seed, scale=0.7):
    rng = np.random.default_rng(seed)
    n = symmetry_orbits(w)[1]
    return PatternFieldPrior(shape, rng.normal(0, scale, n), w, rng.normal(0, scale, n) if two else None)


class TestContractOneScale(PriorContract):
    num_cells = 12
    num_prior_samples = 4000

    def make_prior(self, num_cells):
        return random_field((3, 4), 3, False, 0)


class TestContractTwoScalesOdd(PriorContract):
    """3 x 3 grid, 2 x 2 windows: the pooled grid is 2 x 2 (odd size: blocks of 2 x 2, 2 x 1, 1 x 2, 1 x 1)."""

    num_cells = 9
    num_prior_samples = 4000

    def make_prior(self, num_cells):
        return random_field((3, 3), 2, True, 1, scale=1.0)


def test_orbits():
    assert [symmetry_orbits(w)[1] for w in (1, 2, 3)] == [2, 6, 102]
    orbit, n = symmetry_orbits(3)
    # a code and its transpose / rotation share an orbit
    img = np.arange(9).reshape(3, 3)
    for code in (1, 6, 37, 300):
        bits = (code >> np.arange(9)) & 1
        for t in (img.T, np.rot90(img), np.flipud(img)):
            other = int((bits[t.ravel()] << np.arange(9)).sum())
            assert orbit[other] == orbit[code]
    p = np.random.default_rng(0).normal(size=n)
    np.testing.assert_allclose(table_to_orbits(orbits_to_table(p)), p, rtol=0, atol=1e-14)
    with pytest.raises(ValueError, match="102"):
        PatternFieldPrior((4, 4), np.zeros(7))


def test_pooled_grid_odd_sizes():
    x = torch.zeros(1, 3, 5)
    x[0, 2, 4] = 1.0  # the corner cell pools alone
    x[0, 0, 1] = 1.0
    got = pooled_grid(x)
    assert got.shape == (1, 2, 3)
    assert got[0].tolist() == [[1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]


def test_log_prob_matches_a_direct_sum():
    p = random_field((5, 6), 3, True, 3)
    rng = np.random.default_rng(0)
    m = rng.random((5, 6)) < 0.4
    want = 0.0
    for r in range(3):
        for c in range(4):
            want += p.theta[int((m[r : r + 3, c : c + 3].ravel() << np.arange(9)).sum())]
    pm = np.zeros((3, 3), bool)
    for i in range(3):
        for j in range(3):
            pm[i, j] = m[2 * i : 2 * i + 2, 2 * j : 2 * j + 2].any()
    want += p.theta2[int((pm.ravel() << np.arange(9)).sum())]
    assert abs(float(p.log_prob(torch.from_numpy(m.ravel().astype(float)))) - want) < 1e-12


@pytest.mark.parametrize("shape,w,two", [((6, 8), 3, False), ((7, 9), 3, True), ((5, 5), 2, True), ((9, 6), 3, True)])
def test_compiled_conditionals_equal_log_prob_differences(shape, w, two):
    p = random_field(shape, w, two, 4)
    K = p.num_cells
    rng = np.random.default_rng(1)
    maps = torch.from_numpy((rng.random((12, K)) < rng.uniform(0.2, 0.8, (12, 1))).astype(np.float64))
    on, off = maps[:, None, :].repeat(1, K, 1), maps[:, None, :].repeat(1, K, 1)
    idx = torch.arange(K)
    on[:, idx, idx], off[:, idx, idx] = 1.0, 0.0
    want = (p.log_prob(on) - p.log_prob(off)).numpy()
    for i in range(len(maps)):
        m = maps[i].numpy().astype(np.uint8)
        got = np.array([prior_log_odds(p.compiled(), k, m) for k in range(K)])
        np.testing.assert_allclose(got, want[i], rtol=0, atol=1e-12)
        assert np.array_equal(m, maps[i].numpy().astype(np.uint8))
    R, C = shape
    mm = np.ascontiguousarray(maps.numpy().astype(np.uint8))
    patches = []
    for h, ww in ((3, 3), (2, 2)):
        for r0, c0 in ((0, 0), (R - h, C - ww), (1, 2), (R // 2, 0)):
            patches.append(np.array([(r0 + a) * C + c0 + b for a in range(h) for b in range(ww)], np.int64))
    patches.append(np.array([0, -1, C + 1, 2 * C - 1, -1, K - 1], np.int64))  # pinned / scattered cells
    for patch in patches:
        live = patch[patch >= 0]
        L = len(live)
        cands = np.arange(1 << L, dtype=np.int64)
        got = np.empty((len(maps), len(cands)))
        patch_prior_batch(p.compiled(), mm, patch, cands, got)
        trial = maps[:, None, :].repeat(1, len(cands), 1)
        cfg = ((torch.from_numpy(cands)[:, None] >> torch.arange(L)) & 1).double()
        trial[:, :, torch.from_numpy(live)] = cfg
        d = got - p.log_prob(trial).numpy()
        assert (d.max(1) - d.min(1)).max() < 1e-12, patch


def test_tempered_bundle():
    p = random_field((5, 5), 3, True, 5)
    b = p.compiled().tempered(0.5)
    assert isinstance(b, PatternField)
    np.testing.assert_array_equal(b.theta, 0.5 * p.theta)
    np.testing.assert_array_equal(b.theta2, 0.5 * p.theta2)
    q = p.tempered(0.5)
    m = torch.from_numpy((np.random.default_rng(0).random((4, 25)) < 0.5).astype(float))
    torch.testing.assert_close(q.log_prob(m), 0.5 * p.log_prob(m), rtol=0, atol=1e-12)


def test_outside_occupancy_is_the_stored_marginal_or_an_estimate():
    assert PatternFieldPrior((4, 4), np.zeros(102), occupancy=0.3).outside_occupancy() == 0.3
    # theta = 0: cells independent fair coins; the estimate averages 8 x 32^2 x 10 draws (sd < 0.005)
    assert abs(PatternFieldPrior((4, 4), np.zeros(102)).outside_occupancy() - 0.5) < 0.02


# ------------------------------------------------------------------ exact stationarity
def model_3x3(prior):
    """A 3 x 3 grid seen from two corners (8 latent cells: the pose cells pinned free, 256 maps)."""
    grid = Grid((3, 3), resolution=1.0)
    poses = [[0.5, 0.5, 0.0], [2.5, 2.5, math.pi], [0.5, 0.5, math.pi / 2], [2.5, 2.5, -math.pi / 2]]
    scans = Scans(
        np.array(poses), np.array([0.0]), np.array([[2.2], [1.4], [2.9], [1.2]]), max_range=2.9, over_range="max"
    )
    return OccupancyModel(grid, raycast(grid, scans), GaussianRange(0.9), prior)


@pytest.mark.parametrize(
    "make_kernel",
    [
        lambda m: CellGibbs(m),
        lambda m: PatchGibbs(m, (2, 2)),
        lambda m: PatchGibbs(m, (3, 3)),
    ],
    ids=["cell", "patch2x2", "patch3x3"],
)
@pytest.mark.parametrize("w", [2, 3])
def test_exact_posterior_is_stationary(make_kernel, w):
    model = model_3x3(random_field((3, 3), w, w == 2, 6, scale=1.0))  # w = 2: two scales (pooled 2 x 2)
    assert 6 <= len(model.latent) <= 8
    pi = brute_force(model).log_probs.exp()
    torch.testing.assert_close(pi, torch.softmax(model.log_joint(enumerate_maps(model)), 0), rtol=0, atol=1e-12)
    kernel = make_kernel(model)
    kernel.setup()
    P = sweep_matrix(kernel)
    torch.testing.assert_close(P.sum(1), torch.ones(len(pi), dtype=torch.float64), rtol=0, atol=1e-12)
    torch.testing.assert_close(pi @ P, pi, rtol=0, atol=1e-12)
    assert (P - torch.eye(len(pi), dtype=torch.float64)).abs().max() > 1e-3  # it moves


# ------------------------------------------------------------------ shipped fits
def _write(path, **arrays):
    np.savez(path, **arrays)
    return path


def _good(n=102):
    z = np.zeros(n)
    return dict(
        w=np.array(3), theta=z, occupancy=np.array(0.3), theta2_scale1=z, theta2_scale2=z, occupancy2=np.array(0.3)
    )


def test_load_field_refuses_bad_files(tmp_path):
    assert load_field(_write(tmp_path / "ok.npz", **_good()))["w"] == 3
    (tmp_path / "junk.npz").write_bytes(b"not a zip")
    with pytest.raises(ValueError, match=r"junk\.npz"):
        load_field(tmp_path / "junk.npz")
    bad = _good()
    del bad["theta2_scale2"]
    with pytest.raises(ValueError, match="missing"):
        load_field(_write(tmp_path / "missing.npz", **bad))
    bad = _good()
    bad["theta"] = np.zeros(101)
    with pytest.raises(ValueError, match="shape"):
        load_field(_write(tmp_path / "shape.npz", **bad))
    bad = _good()
    bad["theta"] = np.full(102, np.nan)
    with pytest.raises(ValueError, match="finite"):
        load_field(_write(tmp_path / "nan.npz", **bad))
    bad = _good()
    bad["occupancy"] = np.array(1.5)
    with pytest.raises(ValueError, match="occupancy"):
        load_field(_write(tmp_path / "occ.npz", **bad))
    bad = _good()
    bad["theta"] = np.array(["a"] * 102, dtype=object)
    with pytest.raises(ValueError, match=r"obj\.npz"):
        load_field(_write(tmp_path / "obj.npz", **bad))


@pytest.mark.parametrize("corpus", ["generated", "houseexpo", "ipa", "dungeon"])
def test_shipped_fits_load(corpus):
    d = load_field(field_path(corpus))
    assert d["w"] == 3 and d["theta"].shape == (102,)
    for kind in ("field", "field2"):
        p = prior_by_name(f"{kind}:{corpus}", (8, 9))
        assert isinstance(p, PatternFieldPrior) and p.n_scales == (1 if kind == "field" else 2)
        assert 0.0 <= p.outside_occupancy() <= 1.0
        assert torch.isfinite(p.log_prob(torch.zeros(2, 72))).all()


def test_all_maps_positive():
    p = random_field((2, 3), 2, True, 7, scale=3.0)
    maps = torch.tensor(list(itertools.product([0.0, 1.0], repeat=6)))
    assert torch.isfinite(p.log_prob(maps)).all()


def test_a_field_of_your_own_saves_and_loads_back(tmp_path):
    """``save_field`` writes a fit in the shipped fits' format (one scale alone, or with a two-scale fit) and
    ``field_from_file`` builds the same field from it; fields not tied over the symmetries are refused."""
    from ogm_ppl.priors.pattern_field import field_from_file, load_field, save_field

    one = random_field((6, 7), 3, False, 3)
    one.occupancy = 0.37  # a fitted marginal, stored as given
    two = random_field((6, 7), 3, True, 4)
    two.occupancy = 0.41
    maps = (torch.rand(20, 42, generator=torch.Generator().manual_seed(0)) < 0.4).double()
    p = save_field(tmp_path / "mine.npz", one)
    back = field_from_file(p, (6, 7))
    torch.testing.assert_close(back.log_prob(maps), one.log_prob(maps), rtol=0, atol=1e-12)
    assert back.outside_occupancy() == 0.37 and "theta2_scale1" not in load_field(p)
    with pytest.raises(ValueError, match="one-scale field only"):
        field_from_file(p, (6, 7), scales=2)
    p2 = save_field(tmp_path / "both.npz", one, two)
    back2 = field_from_file(p2, (6, 7), scales=2)
    torch.testing.assert_close(back2.log_prob(maps), two.log_prob(maps), rtol=0, atol=1e-12)
    assert back2.outside_occupancy() == 0.41
    untied = PatternFieldPrior((6, 7), np.arange(512.0) / 512, 3)
    with pytest.raises(ValueError, match="not tied"):
        save_field(tmp_path / "untied.npz", untied)
    assert not (tmp_path / "untied.npz").exists()
