"""Priors over binary maps (Chapter 5) behind one interface (:class:`MapPrior`): the independent prior, the 1D
data-driven prior, pairwise stencil priors and the higher-order MRF (Section 5.2.1), data-driven patch tables
(5.2.2) and border-conditioned tables (5.2.3), a learned multiscale field of patterns and a learned field of a
small network on every window. Each prior hands
the compiled kernels one bundle of arrays (:meth:`MapPrior.compiled`, :mod:`ogm_ppl.priors.compiled`) or none
(the generic path)."""

from ogm_ppl.priors.backoff import BackoffBorderPrior
from ogm_ppl.priors.base import MapPrior
from ogm_ppl.priors.biased import BiasedPrior
from ogm_ppl.priors.border import BorderPatchPrior
from ogm_ppl.priors.data_driven_1d import DataDriven1DPrior
from ogm_ppl.priors.independent import IndependentPrior
from ogm_ppl.priors.local import LocalMapPrior
from ogm_ppl.priors.mrf import MRFPrior, StencilPrior
from ogm_ppl.priors.named import (
    PRIOR_KINDS,
    prior_by_name,
    prior_kinds,
    register_prior,
    unregister_prior,
)
from ogm_ppl.priors.net_field import NetFieldPrior
from ogm_ppl.priors.patch_table import PatchTablePrior
from ogm_ppl.priors.pattern_field import PatternFieldPrior
from ogm_ppl.priors.tables import PriorTables, available_tables, load_tables, tables_by_name
from ogm_ppl.priors.tempered import TemperedPrior

__all__ = [
    "BiasedPrior",
    "BackoffBorderPrior",
    "BorderPatchPrior",
    "DataDriven1DPrior",
    "IndependentPrior",
    "LocalMapPrior",
    "MRFPrior",
    "MapPrior",
    "NetFieldPrior",
    "PRIOR_KINDS",
    "PatchTablePrior",
    "PatternFieldPrior",
    "PriorTables",
    "StencilPrior",
    "TemperedPrior",
    "available_tables",
    "load_tables",
    "prior_by_name",
    "prior_kinds",
    "register_prior",
    "tables_by_name",
    "unregister_prior",
]
