"""Metropolised Gibbs (cells and patches) and scan orders: exact stationarity, the compiled sweeps against
their transition rows, and long runs against brute force."""

import math

import pytest
import torch

from ogm_ppl.inference.exact import brute_force
from ogm_ppl.inference.mcmc.gibbs import CellGibbs, MetropolisCell, PatchGibbs
from ogm_ppl.inference.mcmc.runner import RunningStats, run_gibbs
from ogm_ppl.priors import DataDriven1DPrior
from ogm_ppl.testing import multinomial_goodness_of_fit

from .test_gibbs import (
    MODELS,
    cell_update_matrix,
    code_of,
    exact_pi,
    model_1d,
    patch_update_matrix,
    states,
)
from .test_gibbs_priors import ALL, LONG_RUN, PATCH, make, scene_3x4


def _flip(s, k):
    t = s.clone()
    t[k] = 1 - s[k]
    return t


def metropolised_cell_matrix(kernel, model, k):
    """One metropolised update of cell ``k``: flip with ``min(1, exp(+-lo))``; a state without mass
    (``lo`` nan) moves by a fair coin."""
    S = states(model)
    T = torch.zeros(len(S), len(S), dtype=torch.float64)
    for i, s in enumerate(S):
        kernel.set_state(s)
        lo = kernel.cell_log_odds(int(k))
        if lo != lo:
            a = 0.5
        else:
            d = -lo if s[k] else lo
            a = 1.0 if d >= 0 else (math.exp(d) if d > -math.inf else 0.0)
        T[i, code_of(model, _flip(s, k))] += a
        T[i, i] += 1 - a
    return T


def metropolised_patch_matrix(kernel, model, patch, p_rand=0.0):
    """One metropolised patch update (see ``patch_update_matrix``)."""
    return patch_update_matrix(kernel, model, patch, p_rand, rule="metropolised")


def _all_models():
    return {**{n: MODELS[n] for n in MODELS}, **{n: (lambda n=n: make(n)) for n in ALL}}


@pytest.mark.parametrize("name", list(MODELS) + ALL)
def test_metropolised_cell_update_is_stationary_and_dominates_heat_bath(name):
    model = _all_models()[name]()
    pi = exact_pi(model)
    kernel = CellGibbs(model, update="metropolised")
    kernel.setup()
    eye = torch.eye(len(pi), dtype=torch.float64)
    for k in model.latent.tolist():
        T = metropolised_cell_matrix(kernel, model, k)
        torch.testing.assert_close(T.sum(1), torch.ones(len(pi), dtype=torch.float64), rtol=0, atol=1e-12)
        torch.testing.assert_close(pi @ T, pi, rtol=0, atol=1e-12)
        # Peskun: every off-diagonal move (on states with mass) at least as likely as under heat bath
        H = cell_update_matrix(kernel, model, k)
        live = pi > 0
        assert ((T - H)[live][:, live] * (1 - eye[live][:, live]) >= -1e-12).all()


@pytest.mark.parametrize(
    "name, patch, p_rand",
    [("1d_gauss", 3, 0.0), ("1d_pattern", 2, 0.3), ("2d_gauss", "plus", 0.0), ("1d_wall_prior", 3, 0.2)]
    + [(n, PATCH[n], 0.0) for n in ALL],
)
def test_metropolised_patch_update_is_stationary(name, patch, p_rand):
    model = _all_models()[name]()
    pi = exact_pi(model)
    kernel = PatchGibbs(model, patch, p_rand_patch=p_rand, update="metropolised")
    kernel.setup()
    for p in kernel.patches():
        T = metropolised_patch_matrix(kernel, model, p, p_rand)
        torch.testing.assert_close(T.sum(1), torch.ones(len(pi), dtype=torch.float64), rtol=0, atol=1e-12)
        torch.testing.assert_close(pi @ T, pi, rtol=0, atol=1e-12)


def _draws(kernel, model, start_code, n, seed=5):
    start = states(model)[start_code]
    torch.manual_seed(seed)
    counts = torch.zeros(2 ** len(model.latent), dtype=torch.float64)
    for _ in range(n):
        kernel.set_state(start)
        counts[code_of(model, kernel.sample({"m": start})["m"])] += 1
    return counts


def _check_row(row, counts):
    n = int(counts.sum())
    assert counts[row <= 1e-15].sum() == 0
    big = row * n >= 5  # chi-square needs expected counts of about 5 or more
    assert multinomial_goodness_of_fit(row[big], counts[big], total_count=int(counts[big].sum())) > 1e-3


@pytest.mark.parametrize(
    "name, kind",
    [
        ("1d_gauss", "cell"),
        ("mrf8", "cell"),
        ("border8", "cell"),
        ("1d_gauss", "patch"),
        ("table2x2", "patch"),
        ("border2x2", "patch"),
        ("mrf4", "patch"),
        ("1d_wall_prior", "cell"),
    ],
)
def test_compiled_metropolised_sweep_draws_from_its_transition_row(name, kind):
    """One compiled systematic sweep, repeated from the posterior mode: the next states follow the product
    of the hand-built update matrices (chi-square)."""
    model = _all_models()[name]()
    if kind == "cell":
        kernel = CellGibbs(model, update="metropolised")
        kernel.setup()
        mats = [metropolised_cell_matrix(kernel, model, k) for k in model.latent.tolist()]
    else:
        patch = 3 if name == "1d_gauss" else PATCH[name]
        kernel = PatchGibbs(model, patch, p_rand_patch=0.3, update="metropolised")
        kernel.setup()
        mats = [metropolised_patch_matrix(kernel, model, p, 0.3) for p in kernel.patches()]
    sweep = torch.eye(2 ** len(model.latent), dtype=torch.float64)
    for T in mats:
        sweep = sweep @ T
    i0 = int(torch.argmax(exact_pi(model)))
    n = 1500 if name == "1d_wall_prior" else 4000  # the data-driven prior runs the (slow) generic Python path
    _check_row(sweep[i0], _draws(kernel, model, i0, n))


@pytest.mark.parametrize("name", list(LONG_RUN))
def test_metropolised_long_run_matches_brute_force(name):
    make_prior, patch = LONG_RUN[name]
    model = scene_3x4(make_prior())
    exact = brute_force(model).marginals
    if patch is None:
        kernel = CellGibbs(model, update="metropolised", init="free")
    else:
        kernel = PatchGibbs(model, patch, p_rand_patch=0.05, update="metropolised", init="free")
    n = 4000
    stats = RunningStats(model)
    run_gibbs(kernel, n, stats, warmup=100, seed=2, progress=False)
    # sd of a marginal estimate is at most 0.5 sqrt(tau / n); we allow tau = 20 and 4 sd
    assert (stats.marginals - exact).abs().max() < 4 * 0.5 * math.sqrt(20 / n)


def test_metropolis_cell_takes_any_prior():
    """Flip proposals are symmetric for every prior: with the 1D data-driven prior (generic path) the
    long-run marginals match brute force."""
    model = model_1d(5, prior=DataDriven1DPrior(6, 1))
    exact = brute_force(model).marginals
    n = 3000
    stats = RunningStats(model)
    run_gibbs(MetropolisCell(model, scan="systematic", init="free"), n, stats, warmup=50, seed=4, progress=False)
    assert (stats.marginals - exact).abs().max() < 4 * 0.5 * math.sqrt(20 / n)


class _CountedFactory:
    """``partial(CellGibbs, model, ...)`` that counts how often it is pickled (in this process)."""

    pickled = 0

    def __init__(self, model) -> None:
        self.model = model

    def __call__(self):
        return CellGibbs(self.model, update="metropolised", scan="permutation", init="prior")

    def __reduce__(self):
        type(self).pickled += 1
        return (type(self), (self.model,))


def test_parallel_chains_equal_serial_chains():
    """Chain ``c`` is seeded ``seed + c`` in any process: two worker processes started by the default (forkserver,
    not a fork of this process) give the same statistics as one process, bit for bit, and the pooled marginals
    match brute force. The model is pickled once and sent to each worker (not once a chain), and the caller's
    model is left as it was (its compiled kernels' views of its tensors intact)."""
    import multiprocessing

    from ogm_ppl.inference.mcmc.diagnostics import default_start_method, run_chains

    assert default_start_method() == (
        "forkserver" if "forkserver" in multiprocessing.get_all_start_methods() else "spawn"
    )
    model = model_1d(6, readings=(3.0, 4.0, 3.0))
    make_kernel = _CountedFactory(model)
    serial = run_chains(make_kernel, num_chains=3, num_sweeps=400, trace_cells=[2, 3], warmup=10, seed=11)
    parallel = run_chains(
        make_kernel, num_chains=3, num_sweeps=400, trace_cells=[2, 3], warmup=10, seed=11, processes=2
    )
    assert _CountedFactory.pickled == 1
    again = run_chains(make_kernel, num_chains=3, num_sweeps=400, trace_cells=[2, 3], warmup=10, seed=11)
    for a, b, c in zip(serial.stats, parallel.stats, again.stats):
        assert torch.equal(a.marginals, b.marginals) and torch.equal(a.marginals, c.marginals)
        assert (a.trace() == b.trace()).all()
    assert (serial.rhat() - 1).abs().max() < 0.05
    exact = brute_force(model).marginals
    assert (parallel.marginals - exact).abs().max() < 4 * 0.5 * math.sqrt(10 / 1200)


def test_chains_fork_only_when_asked_and_then_take_a_lambda():
    """``mp_context="fork"`` (asked for) inherits ``make_kernel``, a lambda included, with the same numbers; the
    default start method needs a picklable one and says so before starting any worker."""
    from ogm_ppl.inference.mcmc.diagnostics import run_chains

    model = model_1d(6, readings=(3.0, 4.0, 3.0))
    alone = run_chains(lambda: CellGibbs(model), num_chains=2, num_sweeps=5, trace_cells=[2], seed=3)
    forked = run_chains(
        lambda: CellGibbs(model), num_chains=2, num_sweeps=5, trace_cells=[2], seed=3, processes=2, mp_context="fork"
    )
    assert all(torch.equal(a.marginals, b.marginals) for a, b in zip(forked.stats, alone.stats))
    for ctx in (None, "spawn"):
        with pytest.raises(ValueError, match=r"make_kernel must be picklable .* or mp_context='fork'"):
            run_chains(
                lambda: CellGibbs(model), num_chains=2, num_sweeps=5, trace_cells=[2], processes=2, mp_context=ctx
            )
    with pytest.raises(ValueError, match="mp_context must be one of"):
        run_chains(lambda: CellGibbs(model), num_chains=2, num_sweeps=5, trace_cells=[2], processes=2, mp_context="x")


def test_pyro_mcmc_runs_several_chains_with_a_summary(capsys):
    """``pyro.infer.MCMC(num_chains=2)`` (sequential on a small machine) with the metropolised kernel."""
    import warnings

    import pyro
    from pyro.infer import MCMC

    model = model_1d(6, readings=(3.0, 4.0, 3.0))
    pyro.set_rng_seed(0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # "Chains will be drawn sequentially" on 2 cores
        mcmc = MCMC(
            CellGibbs(model, update="metropolised"),
            num_samples=300,
            warmup_steps=10,
            num_chains=2,
            disable_progbar=True,
        )
        mcmc.run()
    s = mcmc.get_samples(group_by_chain=True)["m"]
    assert s.shape == (2, 300, len(model.latent)) and (s[0] != s[1]).any()
    mcmc.summary()
    assert "r_hat" in capsys.readouterr().out


def test_effective_sample_size_matches_pyro_in_linear_memory():
    """Equal to Pyro's estimator on ordinary chains (AR(1), several chains); finite and bounded by Stan's
    ``N log10 N`` on an alternating chain (Pyro's is negative); 200,000 draws take linear memory."""
    from pyro.ops.stats import effective_sample_size as pyro_ess

    from ogm_ppl.inference.mcmc.diagnostics import effective_sample_size

    g = torch.Generator().manual_seed(0)
    C, N, phi = 3, 2000, 0.6
    x = torch.zeros(C, N, 4, dtype=torch.float64)
    noise = torch.randn(C, N, 4, generator=g, dtype=torch.float64)
    for t in range(1, N):
        x[:, t] = phi * x[:, t - 1] + noise[:, t]
    ours, theirs = effective_sample_size(x), pyro_ess(x, chain_dim=0, sample_dim=1)
    torch.testing.assert_close(ours, theirs, rtol=1e-10, atol=1e-8)
    # AR(1): ESS / (C N) -> (1 - phi) / (1 + phi) = 0.25; the estimate's sd here is about 10 %
    assert (ours / (C * N) - 0.25).abs().max() < 0.1
    alt = (torch.arange(1000) % 2).to(torch.float64).reshape(1, -1, 1)
    assert float(pyro_ess(alt, chain_dim=0, sample_dim=1)) < 0
    assert float(effective_sample_size(alt)) == pytest.approx(1000 * math.log10(1000))
    big = torch.randn(1, 200_000, 2, generator=g, dtype=torch.float64)
    assert (effective_sample_size(big) / 200_000 - 1).abs().max() < 0.05
