"""Inference, one folder per role:

- :mod:`~ogm_ppl.inference.log_odds` — traditional OGM (Section 2.4);
- :mod:`~ogm_ppl.inference.exact` — exact posteriors and the MAP map (Chapters 2-3);
- :mod:`~ogm_ppl.inference.patch_map` — online and offline patch maps (Chapter 3);
- :mod:`~ogm_ppl.inference.mcmc` — Gibbs kernels, the streaming runner, diagnostics (Chapter 4);
- :mod:`~ogm_ppl.inference.variational` — Pyro guides and the Delta fit as amortised VI (Section 2.5).

They share the patch geometry in :mod:`~ogm_ppl.inference.tiling` and the compiled kernels in
``_kernels``; imports point down (roles use kernels and models, never each other's internals, except that
MCMC starts from a log-odds map).

The names of the quick start (:func:`~ogm_ppl.inference.log_odds.evidence_grid`, ``evidence_grid_from_scans``,
``CellGibbs``, ``PatchGibbs``, ``RunningStats``, ``run_gibbs``) are importable from here too; every other name
from its role's package.
"""

from ogm_ppl.inference import exact, log_odds, mcmc, patch_map, variational
from ogm_ppl.inference.log_odds import evidence_grid, evidence_grid_from_scans
from ogm_ppl.inference.mcmc import CellGibbs, PatchGibbs, RunningStats, run_gibbs

__all__ = [
    "CellGibbs",
    "PatchGibbs",
    "RunningStats",
    "evidence_grid",
    "evidence_grid_from_scans",
    "exact",
    "log_odds",
    "mcmc",
    "patch_map",
    "run_gibbs",
    "variational",
]
