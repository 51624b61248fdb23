"""Tests that kill the five mutants that survived the hand mutation test of issue 15.

Each test runs the real code against an answer it does not share a formula with:

* ``test_metropolis_cell_run_matches_brute_force`` and ``test_metropolis_cell_sweep_draws_from_its_row``:
  the compiled metropolised cell update (``_kernels.cell_sweep.new_value``; acceptance sign swapped);
* ``test_data_driven_log_evidence_matches_brute_force``: ``pose_constrained_1d``'s evidence
  (``log(n + 1)`` -> ``log(n)``);
* ``test_mutual_information_of_a_hand_computed_joint`` and ``test_mi_diagonal_is_cell_entropy``:
  ``mutual_information_from_joint`` (symmetrised without the 1/2);
* ``test_resume_restores_torch_rng``: ``run_gibbs`` resumption (torch's RNG state not restored);
* ``test_python_patch_sweep_with_random_patch_mh_matches_brute_force``: ``PatchGibbs._python_sweep``
  (random-patch MH ratio inverted).
"""

import math

import numpy as np
import pytest
import torch
from pyro.distributions.testing.gof import multinomial_goodness_of_fit

from ogm_ppl import OccupancyModel, raycast
from ogm_ppl.datasets import toy_1d
from ogm_ppl.inference.exact import brute_force, pose_constrained_1d
from ogm_ppl.inference.mcmc.gibbs import CellGibbs, MetropolisCell, PatchGibbs
from ogm_ppl.inference.mcmc.runner import RunningStats, run_gibbs
from ogm_ppl.posterior import mutual_information_from_joint
from ogm_ppl.priors import DataDriven1DPrior, IndependentPrior

from .inference.exact.test_exact import model_1d as exact_model_1d
from .inference.mcmc.test_gibbs import (
    _lik,
    code_of,
    exact_pi,
    model_2d,
    patch_update_matrix,
    states,
)
from .inference.mcmc.test_gibbs_priors import IsingByLogProbOnly
from .inference.mcmc.test_gibbs_priors import model_2d as prior_model_2d


def _mc_tol(n: int, tau: float) -> float:
    """4 Monte Carlo standard errors of a marginal estimated from ``n`` sweeps: the sd of a mean of
    0/1 values is at most ``0.5 * sqrt(tau / n)`` for an integrated autocorrelation time ``tau``."""
    return 4 * 0.5 * math.sqrt(tau / n)


def _marginals_of(model, pi: torch.Tensor) -> torch.Tensor:
    return pi @ states(model)


# ----------------------------------------------------------------------------- 1. MetropolisCell


def _metropolis_single_matrix(kernel, model, sign: float = 1.0) -> torch.Tensor:
    """One proposal of ``MetropolisCell``: pick latent cell j with ``q_j``, flip it with probability
    ``min(1, exp(delta))``. ``sign=-1`` builds the mutant (acceptance sign swapped)."""
    q = kernel.proposal_probs()
    S = states(model)
    T = torch.zeros(len(S), len(S), dtype=torch.float64)
    for i, s in enumerate(S):
        kernel._set_state(s)
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
    assert (_marginals_of(model, pi_mut) - exact).abs().max() > 5 * tol


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
        kernel._set_state(start)
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


# ----------------------------------------------------------------------------- 2. evidence


@pytest.mark.parametrize("K, readings, start", [(3, (2.0,), 1), (5, (3.0, 4.0), 1), (7, (2.0, 6.0, 5.0), 1),
                                                (8, (5.0, 5.0, 7.0), 3), (10, (9.0, 1.0), 2)])  # fmt: skip
def test_data_driven_log_evidence_matches_brute_force(K, readings, start):
    for prior in (DataDriven1DPrior(K + 1, start=start), IndependentPrior(torch.linspace(0.15, 0.7, K + 1))):
        model = exact_model_1d(K, readings, prior=prior)
        bf, pc = brute_force(model), pose_constrained_1d(model)
        assert pc.log_evidence == pytest.approx(bf.log_evidence, abs=1e-9), prior


# ----------------------------------------------------------------------------- 3. mutual information


def test_mutual_information_of_a_hand_computed_joint():
    # joint of (a, b): P(00) = 0.4, P(01) = 0.1, P(10) = 0.2, P(11) = 0.3; P(a=1) = 0.5, P(b=1) = 0.4
    mi_ab = (0.4 * math.log(0.4 / (0.5 * 0.6)) + 0.1 * math.log(0.1 / (0.5 * 0.4))
             + 0.2 * math.log(0.2 / (0.5 * 0.6)) + 0.3 * math.log(0.3 / (0.5 * 0.4)))  # fmt: skip
    h_a = math.log(2.0)
    h_b = -(0.4 * math.log(0.4) + 0.6 * math.log(0.6))
    p = torch.tensor([0.5, 0.4], dtype=torch.float64)
    p11 = torch.tensor([[0.5, 0.3], [0.3, 0.4]], dtype=torch.float64)
    expect = torch.tensor([[h_a, mi_ab], [mi_ab, h_b]], dtype=torch.float64)
    torch.testing.assert_close(mutual_information_from_joint(p, p11), expect, rtol=0, atol=1e-12)
    # independent cells: zero; a copy: the entropy
    p11_ind = torch.outer(p, p)
    p11_ind.diagonal().copy_(p)
    torch.testing.assert_close(mutual_information_from_joint(p, p11_ind),
                               torch.diag(torch.tensor([h_a, h_b], dtype=torch.float64)), rtol=0, atol=1e-12)  # fmt: skip


def _entropy(p: torch.Tensor) -> torch.Tensor:
    terms = torch.where((p > 0) & (p < 1), -(p * torch.log(p) + (1 - p) * torch.log1p(-p)), torch.zeros_like(p))
    return terms


def test_mi_diagonal_is_cell_entropy():
    model = model_2d()
    post = brute_force(model)
    mi = post.mutual_information()
    torch.testing.assert_close(mi.diagonal(), _entropy(post.marginals), rtol=0, atol=1e-10)
    # an off-diagonal entry against the pair joint summed directly from the posterior's maps
    S, w = states(model), post.log_probs.exp()
    lat = model.latent
    off = mi[lat][:, lat] - torch.diag(mi[lat, lat])  # the most dependent latent pair, so doubling would show
    a_, b_ = divmod(int(off.argmax()), len(lat))
    i, j = int(lat[a_]), int(lat[b_])
    mi_ij = 0.0
    for a in (0, 1):
        for b in (0, 1):
            pab = float(w[(S[:, i] == a) & (S[:, j] == b)].sum())
            pa, pb = float(w[S[:, i] == a].sum()), float(w[S[:, j] == b].sum())
            mi_ij += pab * math.log(pab / (pa * pb)) if pab > 0 else 0.0
    assert float(mi[i, j]) == pytest.approx(mi_ij, abs=1e-10)
    assert mi_ij > 1e-4  # a pair that is dependent, so doubling would show
    # and the 1D chain posterior agrees on its diagonal too
    toy = toy_1d(num_cells=9, wall=1, readings=(4.0, 5.0, 4.0))
    m1 = OccupancyModel(toy.grid, raycast(toy.grid, toy.scans), model.sensor, DataDriven1DPrior(9, 1))
    pc = pose_constrained_1d(m1)
    torch.testing.assert_close(pc.mutual_information().diagonal(), _entropy(pc.marginals), rtol=0, atol=1e-10)


# ----------------------------------------------------------------------------- 4. resume


@pytest.mark.parametrize("make", [lambda m: CellGibbs(m, init="prior"), lambda m: PatchGibbs(m, 3, p_rand_patch=0.2),
                                  lambda m: MetropolisCell(m)], ids=["cell", "patch", "metropolis"])  # fmt: skip
def test_resume_restores_torch_rng(tmp_path, make):
    """Interrupt, then disturb torch's global generator before resuming: bit for bit all the same."""
    toy = toy_1d(num_cells=16, readings=(6.0, 7.0, 6.0, 9.0))
    model = OccupancyModel(toy.grid, raycast(toy.grid, toy.scans), model_2d().sensor, IndependentPrior(0.3, 16))
    full = run_gibbs(make(model), 300, RunningStats(model, trace_cells=[6]), warmup=10, seed=11, progress=False)
    ck = tmp_path / "ck.npz"
    part = run_gibbs(make(model), 300, RunningStats(model, trace_cells=[6]), warmup=10, seed=11, checkpoint=ck,
                     checkpoint_every=40, stop_after=97, progress=False)  # fmt: skip
    assert part.interrupted and part.sweeps == 97
    torch.manual_seed(999)
    torch.rand(1000)
    rest = run_gibbs(make(model), 300, RunningStats(model, trace_cells=[6]), warmup=10, seed=11, checkpoint=ck,
                     checkpoint_every=40, progress=False)  # fmt: skip
    assert not rest.interrupted and rest.sweeps == 310
    assert np.array_equal(full.state, rest.state)
    assert torch.equal(full.stats.marginals, rest.stats.marginals)
    assert np.array_equal(full.stats.trace(), rest.stats.trace())


# ----------------------------------------------------------------------------- 5. Python-path patch MH


class _IsingLogProbOnly(IsingByLogProbOnly):
    """The log_prob-only Ising prior with a ``sample``, so PatchGibbs takes its Python path."""

    def sample(self, sample_shape=(), generator=None):
        shape = torch.Size(sample_shape) + (self.num_cells,)
        return (torch.rand(shape, generator=generator) < 0.5).to(torch.float64)


def test_python_patch_sweep_with_random_patch_mh_matches_brute_force():
    model = prior_model_2d(lambda s: _IsingLogProbOnly(*s, h=-0.4, J=0.9))
    kernel = PatchGibbs(model, 2, p_rand_patch=0.5)
    kernel.setup()
    assert kernel._local is None and kernel._prior_lo is None  # the generic (Python) sweep
    exact = brute_force(model).marginals
    n = 4000
    stats = RunningStats(model)
    run_gibbs(PatchGibbs(model, 2, p_rand_patch=0.5), n, stats, warmup=100, seed=5, progress=False)
    # the exact integrated autocorrelation time of this sweep is at most 2.2 sweeps over the cells
    # (computed from the sweep matrix); we allow tau = 10: tol = 0.1. The mutant is off by 0.40
    tol = _mc_tol(n, 10)
    err = (stats.marginals - exact).abs().max()
    assert err < tol, (err, tol)
    # the inverted-ratio mutant's sweep has a stationary distribution whose marginals lie far outside
    sweep = torch.eye(2 ** len(model.latent), dtype=torch.float64)
    for p in kernel.patches():
        sweep = sweep @ patch_update_matrix(kernel, model, p, 0.5, sign=-1.0)
    pi_mut = torch.ones(len(sweep), dtype=torch.float64) / len(sweep)
    for _ in range(2000):
        pi_mut = pi_mut @ sweep
    assert (_marginals_of(model, pi_mut) - exact).abs().max() > 3 * tol
