"""MCMC over whole maps (Chapter 4): the map-kernel base, Gibbs kernels for ``pyro.infer.MCMC``, guided
Gibbs, the streaming runner with checkpoints, and convergence diagnostics."""

from ogm_ppl.inference.mcmc.diagnostics import ChainsResult, ess, kl_trace, run_chains, split_rhat
from ogm_ppl.inference.mcmc.gibbs import CellGibbs, MetropolisCell, PatchGibbs
from ogm_ppl.inference.mcmc.guided import GuidedGibbs
from ogm_ppl.inference.mcmc.kernel import KernelStateError, MapKernel, initial_map
from ogm_ppl.inference.mcmc.runner import CheckpointError, GibbsRun, RunningStats, run_gibbs

__all__ = [
    "CellGibbs",
    "ChainsResult",
    "CheckpointError",
    "GibbsRun",
    "GuidedGibbs",
    "KernelStateError",
    "MapKernel",
    "MetropolisCell",
    "PatchGibbs",
    "RunningStats",
    "ess",
    "initial_map",
    "kl_trace",
    "run_chains",
    "run_gibbs",
    "split_rhat",
]
