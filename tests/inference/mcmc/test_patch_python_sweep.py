"""``PatchGibbs._python_sweep`` (the generic path, for a prior with ``log_prob`` only) with random-patch
Metropolis-Hastings moves: long-run marginals against brute force, and the kernel with the MH ratio
inverted lies far outside the tolerance."""

import torch

from ogm_ppl.inference.exact import brute_force
from ogm_ppl.inference.mcmc.gibbs import PatchGibbs
from ogm_ppl.inference.mcmc.runner import RunningStats, run_gibbs

from .test_gibbs import patch_update_matrix
from .test_gibbs_priors import IsingByLogProbOnly
from .test_gibbs_priors import model_2d as prior_model_2d
from .test_metropolis_cell import _mc_tol, marginals_of


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
    assert (marginals_of(model, pi_mut) - exact).abs().max() > 3 * tol
