r"""The compiled face of a prior: one bundle of arrays per kind, and each kind's compiled conditionals.

A Gibbs sweep must never evaluate a prior's whole-map ``log_prob`` per update. A prior that wants the
compiled path returns a bundle from :meth:`~ogm_ppl.priors.MapPrior.compiled` (``None``: the generic path
through :meth:`~ogm_ppl.priors.MapPrior.log_prob_patch`, correct but slow). The kinds (Chapter 5):

* :class:`IndependentCells` — per-cell log-odds (every prior whose ``cell_log_odds()`` is not ``None``
  gets it by default);
* :class:`Stencil` — unary + pairwise weights per offset (:class:`~ogm_ppl.priors.MRFPrior`,
  :class:`~ogm_ppl.priors.StencilPrior`), :mod:`~ogm_ppl.priors.compiled.stencil`;
* :class:`Tiles` — the factors of a tiling's windows (:class:`~ogm_ppl.priors.PatchTablePrior`,
  :class:`~ogm_ppl.priors.BorderPatchPrior`), :mod:`~ogm_ppl.priors.compiled.tiles`;
* :class:`PatternField` — a translation-invariant field of ``w x w`` window patterns at one or two scales
  (:class:`~ogm_ppl.priors.PatternFieldPrior`), :mod:`~ogm_ppl.priors.compiled.field`;
* :class:`NetField` — a small network scored on every ``w x w`` window (:class:`~ogm_ppl.priors.NetFieldPrior`),
  :mod:`~ogm_ppl.priors.compiled.net_field`.

The kernels (``ogm_ppl.inference._kernels``) import this package and nothing else of ``ogm_ppl.priors``;
they call the generic entry points of :mod:`~ogm_ppl.priors.compiled.registry` (``cell_log_odds``,
``patch_prior_weights``, ``patch_candidates``, ``candidate_weights``, ...), which numba resolves to the
registered functions of the bundle's type when it compiles a kernel for that type: one specialised loop
per kind, with no branch on the kind anywhere.

**Adding a kind** is one module: a ``typing.NamedTuple`` bundle (numba takes it as one argument) with the Python
methods every bundle has (:mod:`~ogm_ppl.priors.compiled.bundles`: ``sparse_patches()``, ``patch_capacity(L)``,
``tiles_patches(hw, anchors)``, ``tempered(beta)``, ``biased(h)``, ``factor_extent()``, ``window(...)``), its
compiled conditionals as plain functions numba compiles inline, and one :func:`register` call, which runs when the
module is imported (a kind of your own needs no edit here; a kind shipped with the library is imported below and
named in :data:`CompiledPrior`, the type the kernels' hints use). A prior then returns the bundle from
``compiled()``, and ``ogm_ppl.testing.PriorContract`` checks its conditionals against ``log_prob``.
"""

from ogm_ppl.priors.compiled.bundles import CompiledPrior, IndependentCells, NetField, PatternField, Stencil, Tiles

# the kinds register themselves on import
from ogm_ppl.priors.compiled.field import pattern_field
from ogm_ppl.priors.compiled.independent import independent_cells
from ogm_ppl.priors.compiled.net_field import net_field
from ogm_ppl.priors.compiled.registry import (
    candidate_weights,
    cell_log_odds,
    is_additive,
    kind_of,
    patch_candidates,
    patch_prior_weights,
    register,
    registered,
    scratch_capacity,
)
from ogm_ppl.priors.compiled.sampling import patch_prior_batch, prior_gibbs_sweeps
from ogm_ppl.priors.compiled.stencil import stencil
from ogm_ppl.priors.compiled.tiles import tiles

__all__ = [
    "CompiledPrior",
    "IndependentCells",
    "NetField",
    "PatternField",
    "Stencil",
    "Tiles",
    "candidate_weights",
    "cell_log_odds",
    "independent_cells",
    "is_additive",
    "kind_of",
    "net_field",
    "patch_candidates",
    "patch_prior_batch",
    "patch_prior_weights",
    "pattern_field",
    "prior_gibbs_sweeps",
    "register",
    "registered",
    "scratch_capacity",
    "stencil",
    "tiles",
]
