import math
import os

import numpy as np
import pytest
import torch

from ogm_ppl import GaussianRange, OccupancyModel, PatternMatch, raycast
from ogm_ppl.datasets import THESIS_TOY_READINGS, toy_1d
from ogm_ppl.inference.exact import brute_force, pose_constrained_1d
from ogm_ppl.inference.mcmc.gibbs import CellGibbs, MetropolisCell, PatchGibbs
from ogm_ppl.inference.mcmc.runner import RunningStats, run_gibbs
from ogm_ppl.priors import DataDriven1DPrior, IndependentPrior
from ogm_ppl.testing.kernels import enumerable_1d, enumerable_2d, enumerate_maps

model_1d, model_2d, states = enumerable_1d, enumerable_2d, enumerate_maps


def code_of(model, m) -> int:
    bits = model.full_map(torch.as_tensor(m))[model.latent].long()  # site "m" (L) or a full map (K)
    return int((bits << torch.arange(len(model.latent))).sum())


def exact_pi(model):
    lj = model.log_joint(states(model))
    return torch.softmax(lj, 0)


def cell_update_matrix(kernel, model, k):
    S = states(model)
    T = torch.zeros(len(S), len(S), dtype=torch.float64)
    for i, s in enumerate(S):
        kernel.set_state(s)
        lo = kernel.cell_log_odds(int(k))
        if lo != lo:  # a state the prior rules out: the kernel leaves it unchanged
            T[i, i] = 1.0
            continue
        p1 = 1.0 if lo == math.inf else 0.0 if lo == -math.inf else 1 / (1 + math.exp(-lo))
        for v, p in ((1, p1), (0, 1 - p1)):
            t = s.clone()
            t[k] = v
            T[i, code_of(model, t)] += p
    return T


def patch_update_matrix(kernel, model, patch, p_rand=0.0, sign=1.0, rule="gibbs"):
    """One patch update: Gibbs with probability ``1 - p_rand``, else a uniform proposal accepted by
    Metropolis-Hastings with ``min(1, exp(sign * (logw[w] - logw[cur])))`` (``sign=-1``: an inverted ratio).
    ``rule="metropolised"``: instead of the Gibbs draw, another configuration ``w`` with probability
    ``p_w / (1 - p_cur) * min(1, (1 - p_cur) / (1 - p_w))`` (Liu's metropolised Gibbs)."""
    S = states(model)
    T = torch.zeros(len(S), len(S), dtype=torch.float64)
    live = patch[patch >= 0]
    for i, s in enumerate(S):
        kernel.set_state(s)
        logw = torch.from_numpy(kernel.patch_log_weights(patch))
        W = len(logw)
        if not torch.isfinite(logw).any():  # a state the prior rules out: left unchanged
            T[i, i] = 1.0
            continue
        gibbs = torch.softmax(logw, 0)
        cur = int(sum(int(s[c]) << j for j, c in enumerate(live)))
        if rule == "metropolised":
            p, rest = gibbs, 1.0 - float(gibbs[cur])
            gibbs = torch.zeros(W, dtype=torch.float64)
            for w in range(W):
                if w != cur and rest > 0:
                    gibbs[w] = p[w] / rest * min(1.0, rest / (1.0 - float(p[w]))) if p[w] < 1 else 1.0
            gibbs[cur] = 1.0 - (gibbs.sum() - gibbs[cur])
        mh = torch.zeros(W, dtype=torch.float64)
        for w in range(W):
            a = min(1.0, float(torch.exp(sign * (logw[w] - logw[cur]))))
            mh[w] += a / W
            mh[cur] += (1 - a) / W
        row = (1 - p_rand) * gibbs + p_rand * mh
        for w in range(W):
            t = s.clone()
            t[torch.from_numpy(live)] = torch.tensor([(w >> j) & 1 for j in range(len(live))], dtype=torch.float64)
            T[i, code_of(model, t)] += row[w]
    return T


MODELS = {
    "1d_gauss": lambda: model_1d(),
    "1d_pattern": lambda: model_1d(sensor=PatternMatch(0.7)),
    "2d_gauss": lambda: model_2d(),
    "1d_wall_prior": lambda: model_1d(5, prior=DataDriven1DPrior(6, 1)),
}


@pytest.mark.parametrize("name", list(MODELS))
def test_exact_posterior_is_stationary_for_cell_gibbs(name):
    model = MODELS[name]()
    assert len(model.latent) <= 6
    pi = exact_pi(model)
    torch.testing.assert_close(pi, brute_force(model).log_probs.exp(), rtol=0, atol=1e-12)
    kernel = CellGibbs(model, scan="systematic")
    kernel.setup()
    sweep = torch.eye(len(pi), dtype=torch.float64)
    for k in model.latent.tolist():
        T = cell_update_matrix(kernel, model, k)
        torch.testing.assert_close(T.sum(1), torch.ones(len(pi)), rtol=0, atol=1e-12)
        torch.testing.assert_close(pi @ T, pi, rtol=0, atol=1e-12)
        sweep = sweep @ T
    torch.testing.assert_close(pi @ sweep, pi, rtol=0, atol=1e-12)


@pytest.mark.parametrize(
    "name, patch, p_rand",
    [
        ("1d_gauss", 2, 0.0),
        ("1d_gauss", 3, 0.3),
        ("1d_pattern", 3, 0.0),
        ("2d_gauss", (2, 2), 0.0),
        ("2d_gauss", "plus", 0.2),
        ("1d_wall_prior", 3, 0.0),
        ("1d_wall_prior", 2, 0.25),
    ],
)
def test_exact_posterior_is_stationary_for_patch_gibbs(name, patch, p_rand):
    model = MODELS[name]()
    pi = exact_pi(model)
    kernel = PatchGibbs(model, patch, scan="systematic", p_rand_patch=p_rand)
    kernel.setup()
    for p in kernel.patches():
        T = patch_update_matrix(kernel, model, p, p_rand)
        torch.testing.assert_close(T.sum(1), torch.ones(len(pi)), rtol=0, atol=1e-12)
        torch.testing.assert_close(pi @ T, pi, rtol=0, atol=1e-12)


def test_thesis_random_patch_is_not_exact():
    """Algorithm 2 as printed (random configuration always kept) moves the stationary distribution."""
    model = MODELS["1d_gauss"]()
    pi = exact_pi(model)
    kernel = PatchGibbs(model, 3, scan="systematic")
    kernel.setup()
    p = kernel.patches()[0]
    S = states(model)
    T = torch.zeros(len(S), len(S), dtype=torch.float64)
    live = p[p >= 0]
    for i, s in enumerate(S):
        kernel.set_state(s)
        row = 0.7 * torch.softmax(torch.from_numpy(kernel.patch_log_weights(p)), 0) + 0.3 / 2 ** len(live)
        for w in range(2 ** len(live)):
            t = s.clone()
            t[torch.from_numpy(live)] = torch.tensor([(w >> j) & 1 for j in range(len(live))], dtype=torch.float64)
            T[i, code_of(model, t)] += row[w]
    assert (pi @ T - pi).abs().max() > 1e-3


def test_kl_to_exact_falls_as_one_over_n():
    toy = toy_1d(num_cells=21, readings=THESIS_TOY_READINGS)
    model = OccupancyModel(toy.grid, raycast(toy.grid, toy.scans), GaussianRange(3.0), IndependentPrior(0.5, 21))
    exact = pose_constrained_1d(model).marginals
    from ogm_ppl.inference.mcmc.diagnostics import kl_trace

    checkpoints = [250, 1000, 4000, 16000]
    kls = np.stack([kl_trace(CellGibbs(model), exact, checkpoints, seed=c).numpy() for c in range(8)])
    mean = kls.mean(0)
    slope = np.polyfit(np.log(checkpoints), np.log(mean), 1)[0]
    assert -1.35 < slope < -0.65, (slope, mean)


@pytest.mark.parametrize("L", [1, 3, 5])
def test_patch_gibbs_agrees_with_exact(L):
    toy = toy_1d(num_cells=16, readings=THESIS_TOY_READINGS)
    model = OccupancyModel(toy.grid, raycast(toy.grid, toy.scans), GaussianRange(3.0), IndependentPrior(0.5, 16))
    exact = pose_constrained_1d(model)
    stats = RunningStats(model, rays=[0])
    run_gibbs(PatchGibbs(model, L, scan="systematic"), 6000, stats, warmup=50, seed=L, progress=False)
    # Monte Carlo error: sd of a marginal estimate is at most 0.5 * sqrt(tau / n); tau < 20 here
    tol = 4 * 0.5 * math.sqrt(20 / 6000)
    assert (stats.marginals - exact.marginals).abs().max() < tol
    assert (stats.first_hit(0) - exact.first_hit()).abs().max() < tol


def test_data_driven_prior_gibbs_agrees_with_exact():
    toy = toy_1d(num_cells=12, readings=THESIS_TOY_READINGS)
    model = OccupancyModel(toy.grid, raycast(toy.grid, toy.scans), GaussianRange(3.0), DataDriven1DPrior(12, 1))
    exact = pose_constrained_1d(model)
    stats = RunningStats(model)
    run_gibbs(PatchGibbs(model, 3, p_rand_patch=0.001, init="free"), 1500, stats, warmup=50, seed=0, progress=False)
    assert (stats.marginals - exact.marginals).abs().max() < 4 * 0.5 * math.sqrt(20 / 1500)


def test_resume_is_bit_for_bit(tmp_path):
    toy = toy_1d(num_cells=16, readings=THESIS_TOY_READINGS)
    model = OccupancyModel(toy.grid, raycast(toy.grid, toy.scans), GaussianRange(3.0), IndependentPrior(0.3, 16))

    def stats():
        return RunningStats(model, rays=[0], pairs=[[7, 8]], paths=[[1, 2, 3]], trace_cells=[8])

    for make in (lambda: CellGibbs(model, init="prior"), lambda: PatchGibbs(model, 3)):
        full = run_gibbs(make(), 400, stats(), warmup=10, seed=11, progress=False)
        ck = tmp_path / f"ck{id(make)}.npz"
        part = run_gibbs(
            make(), 400, stats(), warmup=10, seed=11, checkpoint=ck, checkpoint_every=50, stop_after=123, progress=False
        )
        assert part.interrupted and part.sweeps == 123
        rest = run_gibbs(make(), 400, stats(), warmup=10, seed=11, checkpoint=ck, checkpoint_every=50, progress=False)
        assert not rest.interrupted and rest.sweeps == 410
        # the chain's clock goes on from the checkpoint: the interrupted call's time, then this call's
        assert part.seconds_total == part.seconds > 0
        assert rest.seconds_total - rest.seconds == pytest.approx(part.seconds_total, rel=1e-9)
        assert np.array_equal(full.state, rest.state)
        assert torch.equal(full.stats.marginals, rest.stats.marginals)
        assert torch.equal(full.stats.first_hit(0), rest.stats.first_hit(0))
        assert np.array_equal(full.stats.trace(), rest.stats.trace())
        assert not list(tmp_path.glob("*.tmp*"))
    with pytest.raises(ValueError, match="seed"):
        run_gibbs(CellGibbs(model), 400, stats(), seed=12, checkpoint=ck, progress=False)


def test_thinned_samples_on_disk(tmp_path):
    model = model_1d()
    run_gibbs(CellGibbs(model), 20, seed=0, store_every=5, store_dir=tmp_path, progress=False)
    files = sorted(os.listdir(tmp_path))
    assert files == [f"sweep_{i:09d}.npy" for i in (0, 5, 10, 15)]
    m = np.unpackbits(np.load(tmp_path / files[0]))[: model.num_cells]
    assert m.shape == (model.num_cells,) and m[0] == 0


def test_pyro_mcmc_with_running_stats_hook():
    from pyro.infer import MCMC

    model = model_1d()
    stats = RunningStats(model)
    mcmc = MCMC(PatchGibbs(model, 2), num_samples=3000, warmup_steps=50, hook_fn=stats, disable_progbar=True)
    mcmc.run()
    assert mcmc.get_samples()["m"].shape == (3000, len(model.latent))  # site "m": the latent cells
    samples = model.full_map(mcmc.get_samples()["m"])
    assert samples.shape == (3000, model.num_cells) and stats.n == 3000
    torch.testing.assert_close(samples.mean(0), stats.marginals)
    exact = brute_force(model).marginals
    assert (stats.marginals - exact).abs().max() < 4 * 0.5 * math.sqrt(10 / 3000)


def test_bad_arguments():
    model = model_1d()
    with pytest.raises(ValueError, match="scan"):
        CellGibbs(model, scan="sideways")
    with pytest.raises(ValueError, match="p_rand_patch"):
        PatchGibbs(model, 3, p_rand_patch=1.0)
    with pytest.raises(ValueError, match="patch"):
        PatchGibbs(model, (2, 2))  # a 1D grid takes runs only
    with pytest.raises(ValueError, match="init"):
        CellGibbs(model, init="zeros").setup()
    with pytest.raises(ValueError, match="update"):
        CellGibbs(model, update="heat")
    with pytest.raises(ValueError, match="scan='random'"):
        MetropolisCell(model, proposal="endpoint", scan="systematic")


@pytest.mark.parametrize("kernel", ["cell", "patch", "tempering"])
def test_a_start_name_is_checked_when_the_kernel_is_built(kernel, monkeypatch):
    """A named start that initial_map would refuse, or 'guide:CORPUS' of a corpus with no shipped guide, is
    refused by the constructor (the message of corpus_guide), without loading a guide."""
    from ogm_ppl.inference.mcmc.tempering import ParallelTempering
    from ogm_ppl.inference.variational.amortised import AmortisedGuide, unknown_corpus_message

    def make(init):
        if kernel == "cell":
            return CellGibbs(model, init=init)
        if kernel == "patch":
            return PatchGibbs(model, 2, init=init)
        return ParallelTempering(model, [1.0, 0.5], init=init)

    model = model_1d()
    with pytest.raises(ValueError, match="init must be 'ogm', 'prior', 'occupied', 'free', 'guide:CORPUS'"):
        make("zeros")
    with pytest.raises(ValueError, match="or a map of cells, got True"):  # mixing_cycle(model, patch, True)
        make(True)
    with pytest.raises(ValueError) as e:
        make("guide:nope")
    assert str(e.value) == f"init 'guide:nope': {unknown_corpus_message('nope')}"
    with pytest.raises(ValueError, match="did you mean 'houseexpo'"):
        make("guide:HouseExpo")

    def no_load(*a, **k):
        raise AssertionError("a guide was loaded at construction")

    monkeypatch.setattr(AmortisedGuide, "load", classmethod(no_load))
    assert make("guide:houseexpo").init == "guide:houseexpo"
    make(torch.zeros(model.num_cells))  # a map is checked when used


def test_chains_diagnostics():
    from ogm_ppl.inference.mcmc.diagnostics import kl_trace, run_chains

    model = model_1d(8, readings=(4.0, 5.0, 4.0, 6.0))
    res = run_chains(
        lambda: CellGibbs(model, init="prior"), num_chains=4, num_sweeps=800, trace_cells=[3, 4, 5], warmup=20
    )
    assert res.traces().shape == (4, 800, 3)
    rhat, n_eff = res.rhat(), res.ess()
    assert torch.all((rhat - 1).abs() < 0.05), rhat
    assert torch.all(n_eff > 100) and torch.all(n_eff <= 4 * 800 * 1.5)
    exact = brute_force(model).marginals
    assert (res.marginals - exact).abs().max() < 4 * 0.5 * math.sqrt(10 / 3200)
    kl = kl_trace(CellGibbs(model), exact, [100, 1000])
    assert kl[1] < kl[0]
    # a constant cell (pinned cell 0) gets NaN and leaves the others intact
    from ogm_ppl.inference.mcmc.diagnostics import ess

    res0 = run_chains(lambda: CellGibbs(model), num_chains=2, num_sweeps=300, trace_cells=[0, 4])
    e = ess(res0.traces())
    assert torch.isnan(e[0]) and torch.isfinite(e[1])


def _lik(kernel, k):
    """The likelihood part of ``l(m_k | z, m_-k)`` at the kernel's state (Eq. 4.2): log-odds less the
    prior's, for an independent prior."""
    return kernel.cell_log_odds(int(k)) - float(kernel.model.prior.cell_log_odds()[int(k)])


def test_a_start_the_prior_gives_zero_mass_warns_once():
    """An unsmoothed table (``can_be_zero``) that gives the starting map zero mass: setup warns, once per
    kernel; a start inside the support, or a prior without zeros, is silent."""
    import warnings

    from ogm_ppl.inference.mcmc import MasslessStartWarning
    from ogm_ppl.priors import PatchTablePrior
    from ogm_ppl.priors.tempered import TemperedPrior

    table = PatchTablePrior((6,), codes=[0, 3], counts=[3, 1], patch=2)  # tiles 00 and 11 only
    full = PatchTablePrior((6,), codes=[0, 1, 2, 3], counts=[3, 1, 1, 1], patch=2)
    assert table.can_be_zero and TemperedPrior(table, 0.5).can_be_zero
    assert not full.can_be_zero and not IndependentPrior(0.3, 6).can_be_zero
    model = model_1d(K=5, prior=table)  # cell 0 (the robot's) pinned free: cell 1 occupied leaves tile 01
    kernel = PatchGibbs(model, 2, init="occupied")
    with pytest.warns(MasslessStartWarning, match="zero mass under the prior PatchTablePrior"):
        kernel.setup()
    with warnings.catch_warnings():
        warnings.simplefilter("error", MasslessStartWarning)
        kernel.setup()  # once per kernel
        CellGibbs(model, init="free").setup()
        PatchGibbs(model_1d(K=5, prior=full), 2, init="occupied").setup()


def test_pyro_habits_that_do_not_fit_a_kernel_are_named():
    """``CellGibbs(model.model)`` (as ``NUTS(fn)`` takes a function) and ``initial_params`` without the site
    ``m`` get messages that say what to pass, not an AttributeError or a bare KeyError."""
    from pyro.infer import MCMC

    model = model_1d()
    with pytest.raises(TypeError, match=r"takes an OccupancyModel, got method \(pass the OccupancyModel itself"):
        CellGibbs(model.model)
    m = torch.zeros(len(model.latent), dtype=torch.float64)
    with pytest.raises(ValueError, match=r"initial_params must be a dict with the site 'm' .*got \['M'\]"):
        MCMC(CellGibbs(model), num_samples=2, initial_params={"M": m}).run()
    MCMC(CellGibbs(model), num_samples=2, initial_params={"m": m}, disable_progbar=True).run()
