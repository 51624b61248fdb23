"""MCMC over whole maps (Chapter 4): the map-kernel base, Gibbs kernels for ``pyro.infer.MCMC``, guided
Gibbs, parallel tempering, cycles of kernels, the streaming runner with checkpoints, and convergence diagnostics."""

from ogm_ppl.inference.mcmc.chain_state import ChainState
from ogm_ppl.inference.mcmc.cycle import KernelCycle, KernelMixture, mixing_cycle
from ogm_ppl.inference.mcmc.dask_tiles import DaskTileGibbs
from ogm_ppl.inference.mcmc.diagnostics import (
    ChainsResult,
    ess,
    kl_trace,
    rhat_agreement,
    run_chains,
    run_from_starts,
    split_rhat,
    start_maps,
)
from ogm_ppl.inference.mcmc.gibbs import CellGibbs, MetropolisCell, PatchGibbs
from ogm_ppl.inference.mcmc.guided import GuidedGibbs
from ogm_ppl.inference.mcmc.kernel import KernelStateError, MapKernel, MasslessStartWarning, initial_map
from ogm_ppl.inference.mcmc.parallel import ChromaticCellGibbs, ChromaticPatchGibbs
from ogm_ppl.inference.mcmc.runner import CheckpointError, GibbsRun, RunningStats, run_gibbs
from ogm_ppl.inference.mcmc.tempering import ParallelTempering, geometric_ladder, tempered_model

__all__ = [
    "CellGibbs",
    "ChainState",
    "ChainsResult",
    "CheckpointError",
    "ChromaticCellGibbs",
    "ChromaticPatchGibbs",
    "DaskTileGibbs",
    "GibbsRun",
    "GuidedGibbs",
    "KernelCycle",
    "KernelMixture",
    "KernelStateError",
    "MapKernel",
    "MasslessStartWarning",
    "MetropolisCell",
    "ParallelTempering",
    "PatchGibbs",
    "RunningStats",
    "ess",
    "geometric_ladder",
    "initial_map",
    "kl_trace",
    "mixing_cycle",
    "rhat_agreement",
    "run_chains",
    "run_from_starts",
    "run_gibbs",
    "split_rhat",
    "start_maps",
    "tempered_model",
]
