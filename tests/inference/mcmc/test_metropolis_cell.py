"""``MetropolisCell`` (the compiled metropolised cell update, ``_kernels.cell_sweep.new_value``) against
the exact posterior: long-run marginals against brute force, and one sweep's next-state distribution
against the row of its transition matrix. Each test also shows that the kernel with the acceptance sign
swapped lies far outside its tolerance."""

import math

import torch

from ogm_ppl.inference.exact import brute_force
from ogm_ppl.inference.mcmc.gibbs import MetropolisCell
from ogm_ppl.inference.mcmc.runner import RunningStats, run_gibbs
from ogm_ppl.testing import multinomial_goodness_of_fit

from .test_gibbs import _lik, code_of, exact_pi, model_2d, states


def _mc_tol(n: int, tau: float) -> float:
    """4 Monte Carlo standard errors of a marginal estimated from ``n`` sweeps: the sd of a mean of
    0/1 values is at most ``0.5 * sqrt(tau / n)`` for an integrated autocorrelation time ``tau``."""
    return 4 * 0.5 * math.sqrt(tau / n)


def marginals_of(model, pi: torch.Tensor) -> torch.Tensor:
    """The cell marginals of a distribution ``pi`` over the enumerated maps of ``model``."""
    return pi @ states(model)


def _metropolis_single_matrix(kernel, model, sign: float = 1.0) -> torch.Tensor:
    """One proposal of ``MetropolisCell``: pick latent cell j with ``q_j``, flip it with probability
    ``min(1, exp(delta))``. ``sign=-1`` builds the mutant (acceptance sign swapped)."""
    q = kernel.proposal_probs()
    S = states(model)
    T = torch.zeros(len(S), len(S), dtype=torch.float64)
    for i, s in enumerate(S):
        kernel.set_state(s)
        for j, k in enumerate(model.latent.tolist()):
            lo = float(kernel.model.prior.cell_log_odds()[k]) + _lik(kernel, k)
            delta = sign * (-lo if s[k] else lo)
            a = min(1.0, math.exp(delta)) if delta > -math.inf else 0.0
            t = s.clone()
            t[k] = 1 - s[k]
            T[i, code_of(model, t)] += q[j] * a
            T[i, i] += q[j] * (1 - a)
    return T


def test_metropolis_cell_run_matches_brute_force():
    """Long-run marginals of the compiled MetropolisCell sweep equal brute force (7 latent cells)."""
    model = model_2d()
    L = len(model.latent)
    assert L <= 12
    exact = brute_force(model).marginals
    n = 10_000
    stats = RunningStats(model)
    run_gibbs(MetropolisCell(model), n, stats, warmup=100, seed=3, progress=False)
    # the exact integrated autocorrelation time of this sweep (L = 7 flip proposals) is at most 6.8 sweeps
    # over the cells (computed from T^L); we allow tau = 20: tol = 0.089. The mutant is off by 0.96
    tol = _mc_tol(n, 20)
    err = (stats.marginals - exact).abs().max()
    assert err < tol, (err, tol)
    # the swapped-sign mutant is stationary for pi_mut ∝ 1 / pi (a flip is accepted with min(1, p(cur) /
    # p(flip))): its marginals sit far outside the tolerance, so the test above catches it
    kernel = MetropolisCell(model)
    kernel.setup()
    Tm = _metropolis_single_matrix(kernel, model, sign=-1.0)
    pi_mut = torch.ones(len(Tm), dtype=torch.float64) / len(Tm)
    for _ in range(4000):
        pi_mut = pi_mut @ Tm
    assert (marginals_of(model, pi_mut) - exact).abs().max() > 5 * tol


def test_metropolis_cell_sweep_draws_from_its_row():
    """One compiled MetropolisCell sweep (L iid proposals) from a fixed state, repeated: the next states
    follow row ``start`` of ``T^L``, where ``T`` (one proposal) leaves the exact posterior stationary."""
    model = model_2d()
    kernel = MetropolisCell(model)
    kernel.setup()
    pi = exact_pi(model)
    T = _metropolis_single_matrix(kernel, model)
    torch.testing.assert_close(T.sum(1), torch.ones(len(pi), dtype=torch.float64), rtol=0, atol=1e-12)
    torch.testing.assert_close(pi @ T, pi, rtol=0, atol=1e-12)
    L = len(model.latent)
    sweep = torch.linalg.matrix_power(T, L)
    code = 0b1011001 % len(pi)
    start = states(model)[code]
    torch.manual_seed(7)
    counts = torch.zeros(len(pi), dtype=torch.float64)
    draws = 5000
    for _ in range(draws):
        kernel.set_state(start)
        out = kernel.sample({"m": start})["m"]
        counts[code_of(model, out)] += 1
    row = sweep[code]
    assert counts[row == 0].sum() == 0
    big = row * draws >= 5  # chi-square needs expected counts of about 5 or more
    assert multinomial_goodness_of_fit(row[big], counts[big], total_count=int(counts[big].sum())) > 1e-3
    # the mutant's row is far from the right one: total variation well beyond the sampling noise of
    # 5000 draws over <= 128 states (expected TV about sqrt(128 / 5000) / 2 ~ 0.08 at most); it is 0.70
    row_mut = torch.linalg.matrix_power(_metropolis_single_matrix(kernel, model, sign=-1.0), L)[code]
    assert 0.5 * (row - row_mut).abs().sum() > 0.2
