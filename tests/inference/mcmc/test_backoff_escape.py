"""Patch Gibbs on backed-off (strictly positive) tables: the restricted heat bath + escape move is exact
(the brute-force posterior is stationary, the kernel follows the exact matrix, long runs match the
exact marginals), and the thesis's border update is not (its stationary marginals are off by a stated
amount)."""

import numpy as np
import pytest
import torch

from ogm_ppl import OccupancyModel
from ogm_ppl.inference.exact import brute_force
from ogm_ppl.inference.mcmc import CellGibbs, KernelCycle, mixing_cycle
from ogm_ppl.inference.mcmc.gibbs import PatchGibbs
from ogm_ppl.priors import BackoffBorderPrior, BorderPatchPrior
from ogm_ppl.priors.backoff import independent_table
from ogm_ppl.testing import KernelContract
from ogm_ppl.testing.kernels import _check_draws, _codes, enumerable_1d, enumerable_2d, enumerate_maps, sweep_matrix
from ogm_ppl.testing.tile_updates import marginal_gap, stationary, tile_sweep_matrix


def _table(nb, ni, seed, density):
    rng = np.random.default_rng(seed)
    b, i = np.meshgrid(np.arange(2**nb), np.arange(2**ni), indexing="ij")
    counts = rng.integers(1, 9, b.shape).astype(float)
    counts[rng.random(b.shape) > density] = 0
    return b.ravel(), i.ravel(), counts.ravel()


def backoff_prior(shape, seed=0, density=0.3, kappa=0.3):
    """Sparse random counts (most borders seen with a few inners) backed off to independent cells."""
    if len(shape) == 1:
        return BackoffBorderPrior(shape, *_table(2, 2, seed, 0.5), kappa=kappa, back=[0.3, 0.2, 0.2, 0.3], inner=2)
    return BackoffBorderPrior(
        shape, *_table(12, 4, seed, density), kappa=kappa, back=independent_table(0.35, 4), inner=(2, 2)
    )


def with_prior(model, prior):
    return OccupancyModel(model.grid, model.rays, model.sensor, prior)


def _exact(model) -> torch.Tensor:
    return brute_force(model).log_probs.softmax(0)


class TestBackoffEscape(KernelContract):
    """The kernel contract with the exact matrix of the restricted heat bath + escape move."""

    num_draws = 600

    def problem_1d(self):
        return with_prior(enumerable_1d(), backoff_prior((7,)))

    def problem_2d(self):
        return with_prior(enumerable_2d(), backoff_prior((2, 4)))

    def problem_region(self):
        model = super().problem_region()
        return with_prior(model, backoff_prior(model.grid.shape))

    def make_kernel(self, model, region=None):
        return PatchGibbs(model, 2 if model.grid.ndim == 1 else (2, 2), region=region, p_escape=0.5)

    def transition_matrix(self, kernel, rows=None):
        return tile_sweep_matrix(kernel)


class TestBackoffCycle(TestBackoffEscape):
    """Tile sweeps (heat bath + escape) cycled with single-cell Gibbs: ``P = P_tiles P_cells``, exact."""

    def make_kernel(self, model, region=None):
        patch = 2 if model.grid.ndim == 1 else (2, 2)
        return KernelCycle([PatchGibbs(model, patch, region=region, p_escape=0.5), CellGibbs(model, region=region)])

    def transition_matrix(self, kernel, rows=None):
        tiles, cells = kernel.kernels
        return tile_sweep_matrix(tiles) @ sweep_matrix(cells)


class TestBackoffShiftedCycle(TestBackoffEscape):
    """``mixing_cycle(shifted=True)``: tile sweeps (heat bath + escape), single cells, then patches of the tile
    shape on the tiling shifted by a cell (each drawn from its full conditional), exact."""

    supports_region = False  # mixing_cycle builds whole-map parts

    def make_kernel(self, model, region=None):
        return mixing_cycle(model, 2 if model.grid.ndim == 1 else (2, 2), shifted=True)

    def transition_matrix(self, kernel, rows=None):
        tiles, *rest = kernel.kernels
        P = tile_sweep_matrix(tiles)
        for k in rest:
            P = P @ sweep_matrix(k)
        return P


def test_shifted_cycle_leaves_the_posterior_invariant_to_1e_12():
    """The shifted patches straddle the tiles (offset (1, 1) on a 2 x 2 tiling): the cycle's exact one-sweep
    matrix keeps the brute-force posterior to 1e-12, and the shifted sweep alone does too."""
    model = with_prior(enumerable_2d(), backoff_prior((2, 4)))
    k = mixing_cycle(model, (2, 2), shifted=True)
    assert [getattr(p, "offset", None) for p in k.kernels] == [0, None, (1, 1)]
    pi = _exact(model)
    P = TestBackoffShiftedCycle().transition_matrix(k)
    S = sweep_matrix(k.kernels[2])
    for M in (P, S):
        torch.testing.assert_close(M.sum(1), torch.ones(len(pi), dtype=torch.float64), rtol=0, atol=1e-12)
        torch.testing.assert_close(pi @ M, pi, rtol=0, atol=1e-12)
    assert not torch.allclose(S, torch.eye(len(pi), dtype=torch.float64))  # it moves


def test_shifted_needs_the_tile_shape():
    with pytest.raises(ValueError, match="shifted=True needs the tile shape"):
        mixing_cycle(with_prior(enumerable_2d(), backoff_prior((2, 4))), shifted=True)


def test_cycle_leaves_the_posterior_invariant_to_1e_12():
    """The exact one-sweep matrix of the cycle of tile sweeps (heat bath + escape) and single cells, under a
    backed-off border table (the matrix its sweeps follow, ``TestBackoffCycle``): rows sum to 1, ``pi P = pi``
    to 1e-12, and the cycle moves where the tile sweep stays."""
    model = with_prior(enumerable_2d(), backoff_prior((2, 4)))
    k = KernelCycle([PatchGibbs(model, (2, 2), p_escape=0.5), CellGibbs(model)])
    P = TestBackoffCycle().transition_matrix(k)
    T = tile_sweep_matrix(k.kernels[0])
    pi = _exact(model)
    torch.testing.assert_close(P.sum(1), torch.ones(len(pi), dtype=torch.float64), rtol=0, atol=1e-12)
    torch.testing.assert_close(pi @ P, pi, rtol=0, atol=1e-12)
    assert torch.diagonal(P).max() < torch.diagonal(T).max()


def test_cycle_long_run_matches_the_exact_marginals():
    """The cycle of tile and cell sweeps, 10000 sweeps from a fixed seed: each cell's marginal within 5
    batch-means standard errors of the brute-force marginal."""
    model = with_prior(enumerable_2d(), backoff_prior((2, 4)))
    k = KernelCycle([PatchGibbs(model, (2, 2), p_escape=0.2), CellGibbs(model)], init="free")
    exact = _exact(model) @ enumerate_maps(model)[:, model.latent]
    torch.manual_seed(12)
    k.setup()
    n, batches = 10000, 20
    draws = np.empty((n, len(model.latent)))
    params = k.current_params()
    for j in range(n):
        params = k.sample(params)
        draws[j] = params["m"].numpy()
    means = draws.reshape(batches, -1, draws.shape[1]).mean(1)
    se = means.std(0, ddof=1) / np.sqrt(batches)
    err = np.abs(draws.mean(0) - exact.numpy())
    assert (err < 5 * se + 2e-3).all(), (err, se)


@pytest.fixture(scope="module")
def escape_kernel():
    model = with_prior(enumerable_2d(), backoff_prior((2, 4)))
    return PatchGibbs(model, (2, 2), p_escape=0.5)


def test_escape_sweep_leaves_the_posterior_invariant(escape_kernel):
    k = escape_kernel
    assert k._escapes()
    P = tile_sweep_matrix(k)
    pi = _exact(k.model)
    torch.testing.assert_close(P.sum(1), torch.ones(len(pi), dtype=torch.float64), rtol=0, atol=1e-12)
    torch.testing.assert_close(pi @ P, pi, rtol=0, atol=1e-12)
    # the restriction bites: from some states step A stays and only the escape move can leave
    assert int((torch.diagonal(P) > 0.3).sum()) > 0
    # with the escape move the chain is irreducible: its stationary distribution is the posterior alone
    torch.testing.assert_close(stationary(P), pi, rtol=0, atol=1e-9)


def test_escape_kernel_follows_its_matrix_from_a_state_outside_the_support(escape_kernel):
    """From a state whose tile configurations were never counted after their borders, the sweep moves
    only by the escape move: its draws match that row of the exact matrix (chi-square)."""
    k = escape_kernel
    P = tile_sweep_matrix(k)
    i0 = int(torch.argmax(torch.diagonal(P)))
    assert P[i0, i0] < 1.0
    S = enumerate_maps(k.model)
    torch.manual_seed(3)
    n = 3000
    ends = torch.zeros(n, dtype=torch.long)
    for j in range(n):
        k.set_state(S[i0])
        ends[j] = _codes(k.model, k.model.full_map(k.sample(k.current_params())["m"]))
    _check_draws(P[i0], torch.bincount(ends, minlength=len(P)).double(), "escape row")


def test_long_run_matches_the_exact_marginals(escape_kernel):
    """20000 sweeps from a fixed seed: each cell's marginal within 5 batch-means standard errors."""
    k = escape_kernel
    model = k.model
    exact = _exact(model) @ enumerate_maps(model)[:, model.latent]
    torch.manual_seed(11)
    k.set_state(enumerate_maps(model)[0])
    n, batches = 20000, 20
    draws = np.empty((n, len(model.latent)))
    for j in range(n):
        draws[j] = k.sample(k.current_params())["m"].numpy()
    means = draws.reshape(batches, -1, draws.shape[1]).mean(1)
    se = means.std(0, ddof=1) / np.sqrt(batches)
    err = np.abs(draws.mean(0) - exact.numpy())
    assert (err < 5 * se + 2e-3).all(), (err, se)


# ------------------------------------------------------------------ the thesis's border update
#: the thesis update's gap on the problem of test_thesis_update_is_not_exact (computed exactly, seed 4)
THESIS_GAP = {"max_abs_marginal_error": 0.04134117689361638, "total_variation": 0.15254940388666627}


def thesis_problem(update):
    model = with_prior(enumerable_2d(), BorderPatchPrior((2, 4), *_table(12, 4, 4, 1.0), inner=(2, 2)))
    return PatchGibbs(model, (2, 2), update=update)


def test_thesis_update_is_not_exact():
    """Section 5.2.3's update (a tile drawn from ``p(a | border) p(z | a, rest)``) on a full table (every
    configuration counted, so the chain is irreducible): its stationary distribution is not the
    posterior of the tiled joint, while the exact update's is."""
    k = thesis_problem("thesis")
    P = tile_sweep_matrix(k)
    torch.testing.assert_close(P.sum(1), torch.ones(len(P), dtype=torch.float64), rtol=0, atol=1e-12)
    pi = _exact(k.model)
    gap = marginal_gap(k.model, stationary(P), pi)
    assert gap["max_abs_marginal_error"] > 0.01 and gap["total_variation"] > 0.02, gap
    for key, v in THESIS_GAP.items():
        assert abs(gap[key] - v) < 1e-6, (key, gap[key], v)
    exact = thesis_problem("gibbs")
    Pe = tile_sweep_matrix(exact)
    torch.testing.assert_close(pi @ Pe, pi, rtol=0, atol=1e-12)


def test_thesis_kernel_follows_its_matrix():
    k = thesis_problem("thesis")
    P = tile_sweep_matrix(k)
    i0 = 5
    S = enumerate_maps(k.model)
    torch.manual_seed(2)
    n = 2000
    ends = torch.zeros(n, dtype=torch.long)
    for j in range(n):
        k.set_state(S[i0])
        ends[j] = _codes(k.model, k.model.full_map(k.sample(k.current_params())["m"]))
    _check_draws(P[i0], torch.bincount(ends, minlength=len(P)).double(), "thesis row")
    assert k.settings()["update"] == "thesis"


def test_thesis_update_needs_tiles():
    model = enumerable_1d()
    with pytest.raises(ValueError, match="thesis"):
        PatchGibbs(model, 2, update="thesis")


def test_update_rule_is_recorded_and_checked_in_checkpoints():
    from ogm_ppl.inference.mcmc.kernel import KernelStateError

    k = thesis_problem("thesis")
    k.setup()
    state = k.state_dict()
    assert str(state["update"]) == "thesis"
    other = thesis_problem("gibbs")
    with pytest.raises(KernelStateError, match="update=thesis"):
        other.load_state_dict(state)
    thesis_problem("thesis").load_state_dict(state)


def test_gibbs_method_takes_the_thesis_update():
    from ogm_ppl.methods import get_method
    from ogm_ppl.methods.params import ParamError

    m = get_method("gibbs")
    p = m.parse({"patch": [3, 3], "update": "thesis", "p_escape": 0.1})
    assert p.update == "thesis" and p.p_escape == 0.1
    with pytest.raises(ParamError, match="update"):
        m.parse({"patch": 1, "update": "thesis"})
