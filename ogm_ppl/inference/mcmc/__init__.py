"""MCMC over whole maps (Chapter 4): Gibbs kernels for ``pyro.infer.MCMC``, the streaming runner with
checkpoints, and convergence diagnostics."""

from ogm_ppl.inference.mcmc.diagnostics import ChainsResult, ess, kl_trace, run_chains, split_rhat
from ogm_ppl.inference.mcmc.gibbs import CellGibbs, MetropolisCell, PatchGibbs, initial_map
from ogm_ppl.inference.mcmc.runner import CheckpointError, GibbsRun, RunningStats, run_gibbs

__all__ = [
    "CellGibbs", "PatchGibbs", "MetropolisCell", "initial_map",
    "RunningStats", "GibbsRun", "run_gibbs", "CheckpointError",
    "ChainsResult", "run_chains", "split_rhat", "ess", "kl_trace",
]  # fmt: skip

# data-driven MCMC: Gibbs mixed with block proposals from an amortised guide (issue #12 item 3)
from ogm_ppl.inference.mcmc.guided import GuidedGibbs

__all__ += ["GuidedGibbs"]
