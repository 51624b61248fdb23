r"""Variational inference against MCMC: summed KL to the exact posterior against wall-clock time for every
method, on the 1D toy, on the 1000 wall datasets and on small 2D problems solved by brute force.

Every method is scored by the summed cell KL over the latent cells ``L``,

.. math::

    \mathrm{KL} = \sum_{k \in L} p_k \log \frac{p_k}{q_k} + (1 - p_k) \log \frac{1 - p_k}{1 - q_k},

``p_k`` the exact marginal, ``q_k`` the method's clamped to ``[EPS, 1 - EPS]``, and by its wall-clock seconds
(set-up included, the scoring excluded, warm caches; :mod:`~ogm_ppl.studies.vi_vs_mcmc.records`).

Methods (:mod:`~ogm_ppl.studies.vi_vs_mcmc.methods`). One pass: traditional OGM (Hähnel, the fitted p21 and the
fitted neural update term of thesis Section 2.5), online / offline / overlapping patch maps (Chapter 3,
independent priors only), the amortised 2D guide (``ogm_ppl/fitted/guide_amortised.npz``, its one-pass
marginals). Anytime (a curve of KL against seconds): single-cell Gibbs (heat bath and metropolised), patch Gibbs
(Chapter 4), Gibbs mixed with amortised-guide block proposals (2D), and every Pyro guide with every objective
that applies (mean field, patch, first hit; ``TraceGraph_ELBO``, ``ReweightedWakeSleep``, the closed-form
``ExactELBO``).

Problems: the 1D toy and the 4 x 4 grids (:mod:`~ogm_ppl.studies.vi_vs_mcmc.problems`), the wall datasets with
cross-fitted update terms and held-out cross-entropies (:mod:`~ogm_ppl.studies.vi_vs_mcmc.walls`).

:func:`~ogm_ppl.studies.vi_vs_mcmc.study.run` runs the problems of a
:class:`~ogm_ppl.studies.vi_vs_mcmc.records.Settings` (the full run, or :data:`QUICK`) and returns the records;
:func:`~ogm_ppl.studies.vi_vs_mcmc.report.write_results` writes ``results.json``, ``table.md`` and
``kl_vs_time.png`` (:mod:`~ogm_ppl.studies.vi_vs_mcmc.report`).

>>> from ogm_ppl.studies.vi_vs_mcmc import QUICK, Settings
>>> Settings().walls, QUICK.walls
(1000, 50)
"""

from ogm_ppl.studies.vi_vs_mcmc.records import (
    EPS,
    PROBLEMS,
    QUICK,
    TARGET,
    ComparisonSettingsError,
    Record,
    Settings,
    budgets,
    summed_kl,
)
from ogm_ppl.studies.vi_vs_mcmc.report import load_results, plot, replot, table_md, to_json, write_results
from ogm_ppl.studies.vi_vs_mcmc.study import run

__all__ = [
    "EPS",
    "PROBLEMS",
    "QUICK",
    "TARGET",
    "ComparisonSettingsError",
    "Record",
    "Settings",
    "budgets",
    "load_results",
    "plot",
    "replot",
    "run",
    "summed_kl",
    "table_md",
    "to_json",
    "write_results",
]
