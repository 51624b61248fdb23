"""Guided Gibbs (data-driven MCMC with an amortised guide) is exact: every block move leaves the
brute-force posterior stationary (transition matrices over all 2^L maps), the sampler draws from those
matrices, and long runs reproduce brute-force marginals within Monte Carlo error."""

import math

import numpy as np
import pytest
import torch
from pyro.infer import MCMC

from ogm_ppl.inference.exact import brute_force
from ogm_ppl.inference.mcmc import CellGibbs, PatchGibbs, RunningStats, run_gibbs
from ogm_ppl.inference.mcmc.guided import GuidedGibbs
from ogm_ppl.inference.variational.amortised import AmortisedGuide
from ogm_ppl.priors import PatchTablePrior
from ogm_ppl.testing import multinomial_goodness_of_fit

from .test_gibbs import exact_pi, model_2d, states
from .test_gibbs_priors import PRIORS_2D, scene_3x4
from .test_gibbs_priors import model_2d as model_2d_prior


class FixedGuide:
    """A guide given by its logits (duck-typed: ``cell_logits(model)``)."""

    def __init__(self, logits):
        self.logits = torch.as_tensor(logits, dtype=torch.float64)

    def cell_logits(self, model):
        return self.logits


def sharp_guide(model, seed=0):
    """Confident, partly wrong proposals (logits +-3): many rejections, the hard case for exactness."""
    g = torch.Generator().manual_seed(seed)
    return FixedGuide(3.0 * torch.randn(model.num_cells, generator=g, dtype=torch.float64))


MODELS = {
    "independent": lambda: model_2d(),
    "table2x2": lambda: model_2d_prior(PRIORS_2D["table2x2"]),
    "mrf8": lambda: model_2d_prior(PRIORS_2D["mrf8"]),
    "border8": lambda: model_2d_prior(PRIORS_2D["border8"]),
}


def index_of(bits: np.ndarray, latent: np.ndarray) -> np.ndarray:
    """State index (code over the latent cells, as ``states``) of maps ``... x K``."""
    return (bits[..., latent].astype(np.int64) << np.arange(len(latent))).sum(-1)


def block_matrix(kernel, model, cells):
    """Exact transition matrix of one guide move on block ``cells``: propose ``c ~ q_B``, accept with the
    kernel's own ``log_ratio`` (computed for all configurations at once by ``log_ratios``)."""
    S = states(model).numpy()
    latent = model.latent.numpy()
    L = len(cells)
    configs = ((np.arange(2**L)[:, None] >> np.arange(L)) & 1).astype(np.float64)
    logq = kernel.proposal_log_prob(torch.from_numpy(cells), torch.from_numpy(configs)).numpy()
    T = np.zeros((len(S), len(S)))
    for i, s in enumerate(S):
        lr = kernel.log_ratios(s, cells, configs)
        acc = np.exp(np.minimum(lr, 0.0))
        to = np.repeat(s[None, :], len(configs), 0)
        to[:, cells] = configs
        j = index_of(to, latent)
        for jj, p in zip(j, np.exp(logq) * acc):
            if jj != i:
                T[i, jj] += p
        T[i, i] = 1.0 - T[i].sum()
    return T


def pass_matrix(kernel, model, offset):
    S = len(states(model))
    P = np.eye(S)
    for cells, _ in kernel.blocks(offset):
        P = P @ block_matrix(kernel, model, cells)
    return P


@pytest.mark.parametrize("name", list(MODELS))
@pytest.mark.parametrize("block", [(2, 2), (1, 3)])
def test_guide_moves_leave_the_exact_posterior_stationary(name, block):
    """pi P = pi to 1e-10 for every block move of every tiling offset (so for every pass and their
    mixture), with a guide that is confident and often wrong."""
    model = MODELS[name]()
    assert len(model.latent) <= 8
    pi = exact_pi(model).numpy()
    np.testing.assert_allclose(pi, brute_force(model).log_probs.exp().numpy(), rtol=0, atol=1e-12)
    kernel = GuidedGibbs(CellGibbs(model), sharp_guide(model), block=block, p_guide=1.0)
    mix = np.zeros((len(pi), len(pi)))
    for off in kernel.offsets():
        for cells, _ in kernel.blocks(off):
            T = block_matrix(kernel, model, cells)
            assert (T >= -1e-15).all()
            np.testing.assert_allclose(T.sum(1), 1.0, rtol=0, atol=1e-12)
            np.testing.assert_allclose(pi @ T, pi, rtol=0, atol=1e-10)
        mix += pass_matrix(kernel, model, off) / len(kernel.offsets())
    np.testing.assert_allclose(pi @ mix, pi, rtol=0, atol=1e-10)
    assert np.abs(mix - np.eye(len(pi))).max() > 1e-3  # the moves do move


def test_whole_map_independence_sampler_is_stationary():
    model = MODELS["table2x2"]()
    pi = exact_pi(model).numpy()
    kernel = GuidedGibbs(CellGibbs(model), sharp_guide(model, 3), block="all", p_guide=1.0)
    ((cells, _),) = kernel.blocks()
    assert np.array_equal(cells, model.latent.numpy())
    T = block_matrix(kernel, model, cells)
    np.testing.assert_allclose(pi @ T, pi, rtol=0, atol=1e-10)


def test_log_ratio_is_the_log_joint_ratio_times_the_proposal_ratio():
    """The local computation (rays through the block, prior patch differences) equals the full formula."""
    model = MODELS["border8"]()
    guide = sharp_guide(model, 1)
    kernel = GuidedGibbs(CellGibbs(model), guide, block=(2, 2))
    S = states(model)
    lj = model.log_joint(S)
    q = torch.sigmoid(guide.logits)
    rng = np.random.default_rng(0)
    for cells, rays in kernel.blocks((1, 1)):
        for _ in range(20):
            i = int(rng.integers(len(S)))
            new = torch.from_numpy(rng.integers(0, 2, len(cells)).astype(np.float64))
            t = S[i].clone()
            t[torch.from_numpy(cells)] = new
            j = int(index_of(t.numpy(), model.latent.numpy()))
            lq = lambda v: float((v * q[cells].log() + (1 - v) * (1 - q[cells]).log()).sum())
            want = float(lj[j] - lj[i]) + lq(S[i][cells]) - lq(new)
            got = kernel.log_ratio(S[i], cells, new, rays)
            if math.isinf(lj[j]) and math.isinf(lj[i]):
                continue  # both outside the support (through cells away from the block): any value will do
            if math.isinf(lj[j]) or math.isinf(lj[i]):
                assert got == (-math.inf if math.isinf(lj[j]) else math.inf)
            else:
                assert got == pytest.approx(want, abs=1e-9)
                assert kernel.log_ratio(S[i], cells, new) == pytest.approx(got, abs=1e-12)  # rays found


def test_the_sampler_draws_from_its_transition_row():
    """A pass of guide moves from a fixed state, repeated: next states follow the pass's matrix row."""
    model = MODELS["table2x2"]()
    kernel = GuidedGibbs(CellGibbs(model), sharp_guide(model, 2), block=(2, 2), p_guide=1.0, random_offset=False)
    kernel.setup()
    P = pass_matrix(kernel, model, (0, 0))
    pi = exact_pi(model).numpy()
    i0 = int(np.argmax(pi))
    start = states(model)[i0]
    torch.manual_seed(5)
    n = 2000
    counts = np.zeros(len(P))
    latent = model.latent.numpy()
    for _ in range(n):
        out = kernel.sample({"m": start.clone()})["m"]  # a new tensor: the kernel restarts from it
        counts[int(index_of(model.full_map(out).numpy(), latent))] += 1
    row = P[i0]
    assert counts[row == 0].sum() == 0
    big = row * n >= 5
    assert multinomial_goodness_of_fit(torch.from_numpy(row[big]), torch.from_numpy(counts[big]), total_count=n) > 1e-3
    assert kernel.guide_sweeps == n and kernel.acceptance_rate > 0


@pytest.mark.parametrize("base", ["cell", "patch"])
def test_long_run_marginals_match_brute_force(base):
    """Gibbs mixed with guide moves (an untrained network guide) on an 11-cell scene with a table prior."""
    prior = PatchTablePrior((3, 4), np.arange(16), np.r_[20, np.arange(1, 15) % 3 + 1, 6], patch=(2, 2))
    model = scene_3x4(prior)
    exact = brute_force(model).marginals
    inner = CellGibbs(model, init="free") if base == "cell" else PatchGibbs(model, (2, 2), init="free")
    kernel = GuidedGibbs(inner, AmortisedGuide(model, seed=3), block=(2, 3), p_guide=0.5)
    n = 3000
    stats = RunningStats(model)
    run_gibbs(kernel, n, stats, warmup=50, seed=1, progress=False)
    # sd of a marginal estimate is at most 0.5 sqrt(tau / n); we allow tau = 20 and 4 sd
    assert (stats.marginals - exact).abs().max() < 4 * 0.5 * math.sqrt(20 / n)
    assert kernel.guide_sweeps > 0.4 * (n + 50) and kernel.acceptance_rate > 0.01


def test_guide_only_chain_matches_brute_force():
    """p_guide = 1 with whole-map proposals: the independence sampler alone is exact."""
    model = MODELS["mrf8"]()
    exact = brute_force(model).marginals
    kernel = GuidedGibbs(CellGibbs(model), AmortisedGuide(model, seed=0), block="all", p_guide=1.0, init="base")
    n = 4000
    stats = RunningStats(model)
    run_gibbs(kernel, n, stats, seed=2, progress=False)
    assert (stats.marginals - exact).abs().max() < 4 * 0.5 * math.sqrt(20 / n)


def test_pyro_mcmc_and_checkpoint_resume(tmp_path):
    model = MODELS["independent"]()
    guide = AmortisedGuide(model, seed=0)
    kernel = GuidedGibbs(CellGibbs(model), guide, block=(2, 2))
    mcmc = MCMC(kernel, num_samples=30, warmup_steps=5, disable_progbar=True)
    mcmc.run()
    assert mcmc.get_samples()["m"].shape == (30, len(model.latent))
    assert torch.equal(kernel.initial_params["m"], (guide.marginals(model) > 0.5).double()[model.latent])
    # an interrupted and resumed run equals an uninterrupted one, bit for bit
    full = run_gibbs(GuidedGibbs(CellGibbs(model), guide, block=(2, 2)), 40, seed=4, progress=False)
    ck = tmp_path / "c.npz"
    part = run_gibbs(
        GuidedGibbs(CellGibbs(model), guide, block=(2, 2)), 40, seed=4, progress=False, checkpoint=ck, stop_after=17
    )
    assert part.interrupted
    rest = run_gibbs(GuidedGibbs(CellGibbs(model), guide, block=(2, 2)), 40, seed=4, progress=False, checkpoint=ck)
    assert np.array_equal(rest.state, full.state)
    torch.testing.assert_close(rest.stats.marginals, full.stats.marginals, rtol=0, atol=0)


def test_bad_arguments():
    model = MODELS["independent"]()
    g = sharp_guide(model)
    with pytest.raises(ValueError, match="p_guide"):
        GuidedGibbs(CellGibbs(model), g, p_guide=1.5)
    with pytest.raises(ValueError, match="init"):
        GuidedGibbs(CellGibbs(model), g, init="ogm")
    with pytest.raises(ValueError, match="block"):
        GuidedGibbs(CellGibbs(model), g, block="rows")
    with pytest.raises(ValueError, match="cell_logits"):
        GuidedGibbs(CellGibbs(model), FixedGuide(torch.zeros(3)))
    k = GuidedGibbs(CellGibbs(model), g, block=(2, 2))
    pinned = int(np.flatnonzero(model.known_free.numpy())[0])
    assert k.log_ratio(torch.zeros(model.num_cells), np.array([pinned]), np.array([1.0])) == -math.inf


def tile_model():
    """2 x 4 grid, 2 x 2 tiles, 7 latent cells."""
    return model_2d_prior(PRIORS_2D["table2x2"])


@pytest.mark.parametrize("block", [(2, 2), (2, 4)])
def test_tile_proposals_leave_the_exact_posterior_stationary(block):
    """proposal='tiles': each tile of the block from its table tilted by the guide; exact MH as well."""
    model = tile_model()
    pi = exact_pi(model).numpy()
    kernel = GuidedGibbs(CellGibbs(model), sharp_guide(model, 4), block=block, p_guide=1.0, proposal="tiles")
    assert kernel.offsets() == ([(0, 0)] if block == (2, 2) else [(0, 0), (0, 2)])  # aligned to the tiles
    for off in kernel.offsets():
        for cells, _ in kernel.blocks(off):
            L = len(cells)
            configs = ((np.arange(2**L)[:, None] >> np.arange(L)) & 1).astype(np.float64)
            q = kernel.proposal_log_prob(cells, configs).exp()
            assert float(q.sum()) == pytest.approx(1.0, abs=1e-12)  # a normalised proposal over the block
            T = block_matrix(kernel, model, cells)
            np.testing.assert_allclose(T.sum(1), 1.0, rtol=0, atol=1e-12)
            np.testing.assert_allclose(pi @ T, pi, rtol=0, atol=1e-10)
    # the sampler draws from the proposal it scores; a configuration the table rules out is never proposed
    cells, _ = kernel.blocks((0, 0))[0]
    L = len(cells)
    configs = ((np.arange(2**L)[:, None] >> np.arange(L)) & 1).astype(np.float64)
    q = kernel.proposal_log_prob(cells, configs).exp()
    n = 2000
    draws = np.stack([kernel._propose(cells) for _ in range(n)])
    counts = torch.from_numpy(
        np.bincount((draws.astype(np.int64) << np.arange(L)).sum(1), minlength=2**L).astype(np.float64)
    )
    assert counts[q == 0].sum() == 0
    big = q * n >= 5
    assert multinomial_goodness_of_fit(q[big], counts[big], total_count=n) > 1e-3


def test_tile_proposal_chain_matches_brute_force():
    prior = PatchTablePrior((3, 4), np.arange(16), np.r_[20, np.arange(1, 15) % 3 + 1, 6], patch=(2, 2))
    model = scene_3x4(prior)
    exact = brute_force(model).marginals
    kernel = GuidedGibbs(
        PatchGibbs(model, (2, 2)), AmortisedGuide(model, seed=5), block=(2, 2), p_guide=0.5, proposal="tiles"
    )
    n = 2000
    stats = RunningStats(model)
    run_gibbs(kernel, n, stats, warmup=50, seed=3, progress=False)
    assert (stats.marginals - exact).abs().max() < 4 * 0.5 * math.sqrt(20 / n)
    assert kernel.acceptance_rate > 0.05
    with pytest.raises(ValueError, match="whole 2 x 2 tiles"):
        GuidedGibbs(PatchGibbs(model, (2, 2)), AmortisedGuide(model), block=(3, 3), proposal="tiles")
    with pytest.raises(ValueError, match="tile prior"):
        GuidedGibbs(CellGibbs(model_2d()), sharp_guide(model_2d()), block=(2, 2), proposal="tiles")
