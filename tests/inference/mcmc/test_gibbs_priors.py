"""Gibbs sampling with the correlated priors of Chapter 5 is exact: every single-cell and patch transition
leaves the brute-force posterior stationary, the compiled sweeps draw from those transitions, and long
runs of the compiled sweeps reproduce brute-force marginals within Monte Carlo error."""

import math

import numpy as np
import pytest
import torch

from ogm_ppl import GaussianRange, Grid, OccupancyModel, Scans, raycast
from ogm_ppl.datasets import simple_2d_example
from ogm_ppl.inference.exact import brute_force
from ogm_ppl.inference.exact.map_estimate import map_estimate
from ogm_ppl.inference.mcmc.gibbs import CellGibbs, PatchGibbs
from ogm_ppl.inference.mcmc.runner import RunningStats, run_gibbs
from ogm_ppl.priors import BorderPatchPrior, MapPrior, MRFPrior, PatchTablePrior, StencilPrior
from ogm_ppl.testing import multinomial_goodness_of_fit
from ogm_ppl.testing.kernels import enumerable_2d

from .test_gibbs import cell_update_matrix, code_of, exact_pi, model_1d, patch_update_matrix, states


def _table(nb, ni, seed, density=1.0):
    rng = np.random.default_rng(seed)
    b, i = np.meshgrid(np.arange(2**nb), np.arange(2**ni), indexing="ij")
    c = rng.integers(1, 6, b.shape).astype(float)
    c[rng.random(b.shape) > density] = 0
    return b.ravel(), i.ravel(), c.ravel()


def model_2d(prior_fn, sensor=None):
    """The 2 x 4 enumerable problem of ``ogm_ppl.testing.kernels`` (7 latent cells) under ``prior_fn((2, 4))``."""
    return enumerable_2d(sensor, prior=prior_fn((2, 4)))


PRIORS_1D = {
    "mrf1": lambda s: MRFPrior(s, order=1, psi=0.4, cell_prior=0.3),
    "mrf2": lambda s: MRFPrior(s, order=2, psi=0.6, cell_prior=0.4),
    "table3": lambda s: PatchTablePrior(s, np.arange(8), [6, 1, 0, 2, 1, 1, 3, 5], patch=3),
    "border1": lambda s: BorderPatchPrior(s, *_table(2, 1, 0), inner=1),
    "border2": lambda s: BorderPatchPrior(s, *_table(2, 2, 1, density=0.6), inner=2),
}
PRIORS_2D = {
    "mrf4": lambda s: MRFPrior(s, order=1, psi=0.3, cell_prior=0.4),
    "mrf8": lambda s: MRFPrior(s, order=2, psi=0.5, cell_prior=0.3),
    "table2x2": lambda s: PatchTablePrior(s, np.arange(16), np.r_[9, np.arange(1, 15) % 4, 5], patch=(2, 2)),
    "border8": lambda s: BorderPatchPrior(s, *_table(8, 1, 2, density=0.5), inner=(1, 1)),
    "border2x2": lambda s: BorderPatchPrior(s, *_table(12, 4, 3, density=0.01), inner=(2, 2)),
}


def make(name):
    if name in PRIORS_1D:
        return model_1d(prior=PRIORS_1D[name]((7,)))
    return model_2d(PRIORS_2D[name])


ALL = list(PRIORS_1D) + list(PRIORS_2D)
PATCH = {
    "mrf1": 3,
    "mrf2": 2,
    "table3": 3,
    "border1": 2,
    "border2": 2,
    "mrf4": (2, 2),
    "mrf8": "plus",
    "table2x2": (2, 2),
    "border8": (1, 2),
    "border2x2": (2, 2),
}


@pytest.mark.parametrize("name", ALL)
def test_exact_posterior_is_stationary_for_cell_gibbs(name):
    model = make(name)
    pi = exact_pi(model)
    torch.testing.assert_close(pi, brute_force(model).log_probs.exp(), rtol=0, atol=1e-12)
    kernel = CellGibbs(model)
    kernel.setup()
    assert kernel._local is not None  # the compiled local conditional, not the generic path
    for k in model.latent.tolist():
        T = cell_update_matrix(kernel, model, k)
        torch.testing.assert_close(T.sum(1), torch.ones(len(pi)), rtol=0, atol=1e-12)
        torch.testing.assert_close(pi @ T, pi, rtol=0, atol=1e-12)


@pytest.mark.parametrize("name", ALL)
@pytest.mark.parametrize("p_rand", [0.0, 0.3])
def test_exact_posterior_is_stationary_for_patch_gibbs(name, p_rand):
    model = make(name)
    pi = exact_pi(model)
    kernel = PatchGibbs(model, PATCH[name], p_rand_patch=p_rand)
    kernel.setup()
    for p in kernel.patches():
        T = patch_update_matrix(kernel, model, p, p_rand)
        torch.testing.assert_close(T.sum(1), torch.ones(len(pi)), rtol=0, atol=1e-12)
        torch.testing.assert_close(pi @ T, pi, rtol=0, atol=1e-12)


@pytest.mark.parametrize(
    "name, kind",
    [("mrf8", "cell"), ("border8", "cell"), ("table2x2", "patch"), ("border2x2", "patch"), ("mrf4", "patch")],
)
def test_compiled_sweep_draws_from_its_transition_row(name, kind):
    """One compiled sweep from a fixed state, repeated: next states follow the product of the update
    matrices (for tiles of table priors the compiled sweep enumerates the sparse support only)."""
    model = make(name)
    if kind == "cell":
        kernel = CellGibbs(model)
        kernel.setup()
        mats = [cell_update_matrix(kernel, model, k) for k in model.latent.tolist()]
    else:
        kernel = PatchGibbs(model, PATCH[name], p_rand_patch=0.3)
        kernel.setup()
        mats = [patch_update_matrix(kernel, model, p, 0.3) for p in kernel.patches()]
    sweep = torch.eye(2 ** len(model.latent), dtype=torch.float64)
    for T in mats:
        sweep = sweep @ T
    pi = exact_pi(model)
    i0 = int(torch.argmax(pi))
    start = states(model)[i0]
    torch.manual_seed(5)
    n = 6000
    counts = torch.zeros(len(sweep), dtype=torch.float64)
    for _ in range(n):
        kernel.set_state(start)
        counts[code_of(model, kernel.sample({"m": start})["m"])] += 1
    row = sweep[i0]
    assert counts[row == 0].sum() == 0
    big = row * n >= 5
    assert multinomial_goodness_of_fit(row[big], counts[big], total_count=n) > 1e-3


def scene_3x4(prior):
    """A 3 x 4 grid (11 latent cells) seen by three poses: small enough for brute force."""
    grid = Grid((3, 4), resolution=1.0)
    scans = Scans(
        [[0.5, 0.5, 0.0], [0.5, 0.5, 0.6], [3.5, 2.5, math.pi], [3.5, 2.5, -2.2]],
        [0.0],
        [[2.6], [3.5], [2.2], [1.3]],
        max_range=3.5,
        over_range="max",
    )
    return OccupancyModel(grid, raycast(grid, scans), GaussianRange(0.8), prior)


LONG_RUN = {
    "mrf8-cell": (lambda: MRFPrior((3, 4), order=2, psi=0.5, cell_prior=0.3), None),
    "table-patch": (
        lambda: PatchTablePrior((3, 4), np.arange(16), np.r_[20, np.arange(1, 15) % 3 + 1, 6], patch=(2, 2)),
        (2, 2),
    ),
    "border-cell": (lambda: BorderPatchPrior((3, 4), *_table(8, 1, 4), inner=(1, 1)), None),
    "border-patch": (lambda: BorderPatchPrior((3, 4), *_table(12, 4, 5), inner=(2, 2)), (2, 2)),
}


@pytest.mark.parametrize("name", list(LONG_RUN))
def test_long_run_marginals_match_brute_force(name):
    make_prior, patch = LONG_RUN[name]
    model = scene_3x4(make_prior())
    assert len(model.latent) <= 14
    exact = brute_force(model).marginals
    kernel = (
        CellGibbs(model, init="free") if patch is None else PatchGibbs(model, patch, p_rand_patch=0.05, init="free")
    )
    n = 4000
    stats = RunningStats(model)
    run_gibbs(kernel, n, stats, warmup=100, seed=1, progress=False)
    # sd of a marginal estimate is at most 0.5 sqrt(tau / n); we allow tau = 20 and 4 sd
    assert (stats.marginals - exact).abs().max() < 4 * 0.5 * math.sqrt(20 / n)


class IsingByLogProbOnly(MapPrior):
    """What a researcher writes first: only ``log_prob`` (here a 4-connected Ising prior)."""

    def __init__(self, rows, cols, h, J):
        self.rows, self.cols, self.h, self.J = rows, cols, h, J
        self.num_cells = rows * cols

    def log_prob(self, maps):
        x = torch.as_tensor(maps, dtype=torch.float64)
        g = x.reshape(*x.shape[:-1], self.rows, self.cols)
        pair = (g[..., 1:, :] * g[..., :-1, :]).sum((-2, -1)) + (g[..., :, 1:] * g[..., :, :-1]).sum((-2, -1))
        return self.h * x.sum(-1) + self.J * pair


def test_user_prior_on_the_2d_example_generic_and_stencil_agree():
    """A log_prob-only prior runs (no overflow) on the 64 x 64 example; the same prior written as a
    StencilPrior runs compiled and makes the very same moves from the same random numbers."""
    ex = simple_2d_example()
    rays = raycast(ex.grid, ex.scans)
    h, J = -1.2, 1.5
    slow = OccupancyModel(ex.grid, rays, GaussianRange(3.0), IsingByLogProbOnly(64, 64, h, J))
    fast = OccupancyModel(
        ex.grid,
        rays,
        GaussianRange(3.0),
        # outside=0.5: the log_prob-only prior's occupancy beyond the grid edge (the base class's default)
        StencilPrior((64, 64), unary=h, offsets=[(0, 1), (1, 0)], coupling=J, outside=0.5),
    )
    ks, kf = CellGibbs(slow), CellGibbs(fast)
    ks.setup()
    kf.setup()
    assert ks._local is None and kf._local is not None
    assert np.array_equal(ks.state, kf.state)
    m = torch.from_numpy(ks.state.astype(np.float64))
    torch.manual_seed(3)
    a = ks.sample({"m": m})["m"]
    torch.manual_seed(3)
    b = kf.sample({"m": m})["m"]
    assert torch.equal(a, b) and (slow.full_map(a) != m).any()
    # and the log-odds of every cell agree
    for k in (0, 65, 1000, 2080, 4095):
        assert ks.cell_log_odds(k) == pytest.approx(kf.cell_log_odds(k), abs=1e-9)


def test_five_by_five_patches_with_a_table_prior():
    """2^25 configurations are refused for the independent prior but sampled over the table's sparse
    support when the table's tiles are the patches."""
    ex = simple_2d_example()
    rays = raycast(ex.grid, ex.scans)
    from ogm_ppl.priors import IndependentPrior

    with pytest.raises(ValueError, match="configurations"):
        PatchGibbs(OccupancyModel(ex.grid, rays, GaussianRange(3.0), IndependentPrior(0.3, 4096)), (5, 5))
    truth = torch.from_numpy(ex.truth.astype(np.float64))
    win = torch.nn.functional.unfold(truth[None, None], 5).long()[0]  # 25 x n, row-major window cells
    codes = (win << torch.arange(25)[:, None]).sum(0)
    u, c = torch.unique(codes, return_counts=True)
    prior = PatchTablePrior((64, 64), u.numpy(), c.numpy(), patch=(5, 5), mass=0.999)
    model = OccupancyModel(ex.grid, rays, GaussianRange(3.0), prior)
    kernel = PatchGibbs(model, (5, 5), p_rand_patch=0.001)
    with pytest.raises(ValueError, match="aligned"):
        PatchGibbs(model, (5, 5), offset=(1, 2))
    kernel.setup()
    m = torch.from_numpy(kernel.state.astype(np.float64))
    for _ in range(3):
        m = model.full_map(kernel.sample({"m": m})["m"])
    assert torch.isfinite(model.log_joint(m))


def test_map_estimate_uses_the_local_conditional():
    model = scene_3x4(MRFPrior((3, 4), order=1, psi=0.3, cell_prior=0.3))
    est = map_estimate(model, init="occupied")
    assert est.converged
    # a local maximum: no single flip raises the log joint
    for k in model.latent.tolist():
        t = est.map.clone()
        t[k] = 1 - t[k]
        assert model.log_joint(t) <= est.log_joint + 1e-9
