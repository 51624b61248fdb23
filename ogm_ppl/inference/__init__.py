"""Inference, one folder per role:

- :mod:`~ogm_ppl.inference.log_odds` — traditional OGM (Section 2.4);
- :mod:`~ogm_ppl.inference.exact` — exact posteriors and the MAP map (Chapters 2-3);
- :mod:`~ogm_ppl.inference.patch_map` — online and offline patch maps (Chapter 3);
- :mod:`~ogm_ppl.inference.mcmc` — Gibbs kernels, the streaming runner, diagnostics (Chapter 4);
- :mod:`~ogm_ppl.inference.variational` — Pyro guides and the Delta fit as amortised VI (Section 2.5).

They share the patch geometry in :mod:`~ogm_ppl.inference.tiling` and the compiled kernels in
``_kernels``; imports point down (roles use kernels and models, never each other's internals, except that
MCMC starts from a log-odds map).
"""

from ogm_ppl.inference import exact, log_odds, mcmc, patch_map, variational
from ogm_ppl.inference.exact import MapEstimate, map_estimate
from ogm_ppl.inference.log_odds import LogOddsMap, evidence_grid, evidence_grid_from_scans
from ogm_ppl.inference.mcmc import (
    CellGibbs,
    CheckpointError,
    GibbsRun,
    KernelCycle,
    KernelMixture,
    MetropolisCell,
    ParallelTempering,
    PatchGibbs,
    RunningStats,
    geometric_ladder,
    run_gibbs,
    tempered_model,
)
from ogm_ppl.inference.variational import (
    ExactELBO,
    FirstHitGuide,
    MeanFieldGuide,
    PatchGuide,
    fit_guide,
)

__all__ = [
    "CellGibbs",
    "CheckpointError",
    "ExactELBO",
    "FirstHitGuide",
    "GibbsRun",
    "KernelCycle",
    "KernelMixture",
    "LogOddsMap",
    "MapEstimate",
    "MeanFieldGuide",
    "MetropolisCell",
    "ParallelTempering",
    "PatchGibbs",
    "PatchGuide",
    "RunningStats",
    "evidence_grid",
    "evidence_grid_from_scans",
    "exact",
    "fit_guide",
    "geometric_ladder",
    "log_odds",
    "map_estimate",
    "mcmc",
    "patch_map",
    "run_gibbs",
    "tempered_model",
    "variational",
]
