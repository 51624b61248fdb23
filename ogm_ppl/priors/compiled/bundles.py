"""The bundles of arrays a prior hands to the compiled kernels (:meth:`MapPrior.compiled`), one per kind.

Each bundle is a ``typing.NamedTuple`` built by keyword (numba takes it as one argument and compiles one
specialisation of a kernel per bundle type), defined in its kind's module beside its compiled conditionals
(:mod:`~ogm_ppl.priors.compiled.independent`, :mod:`~ogm_ppl.priors.compiled.stencil`,
:mod:`~ogm_ppl.priors.compiled.tiles`, :mod:`~ogm_ppl.priors.compiled.field`,
:mod:`~ogm_ppl.priors.compiled.net_field`); the kernels never look at which
kind they hold. The Python methods every bundle has:

* ``sparse_patches()``, ``patch_capacity(L)``, ``tiles_patches(hw, anchors)`` — how many candidate
  configurations a patch update may weigh, and whether patches larger than 20 cells are possible;
* ``tempered(beta)``, ``biased(h)`` — the bundle of ``p~(m)^beta`` and of ``p~(m) exp(h sum_k m_k)``;
* ``factor_extent()`` — the largest extent of a factor in cells (what the chromatic tilings need);
* ``window(grid_cols, r0, c0, rows, cols)`` — the bundle restricted to a window (``TypeError`` where the kind
  is anchored to the whole grid).
"""

from __future__ import annotations

from ogm_ppl.priors.compiled.field import PatternField
from ogm_ppl.priors.compiled.independent import IndependentCells
from ogm_ppl.priors.compiled.net_field import NetField
from ogm_ppl.priors.compiled.stencil import Stencil
from ogm_ppl.priors.compiled.tiles import Tiles

__all__ = ["CompiledPrior", "IndependentCells", "NetField", "PatternField", "Stencil", "Tiles"]

#: any bundle a prior's ``compiled()`` may return (a shipped kind adds its class here)
CompiledPrior = IndependentCells | Stencil | Tiles | PatternField | NetField
