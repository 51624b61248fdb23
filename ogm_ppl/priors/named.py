r"""Priors by name, built from the learned tables shipped in ``ogm_ppl/fitted`` (Chapter 5).

A name is ``KIND`` or ``KIND:CORPUS``; ``CORPUS`` is one of :func:`~ogm_ppl.priors.tables.available_tables`
(``generated``, ``houseexpo``, ``ipa``, ``dungeon``; default ``houseexpo``, the real floor plans whose
statistics are closest to the thesis's):

========================  ==========================================================================
``independent``           cells independent, ``lambda = 0.5`` (the uniform prior of Chapters 2-4)
``independent:CORPUS``    cells independent, ``lambda`` = the corpus's occupied share (thesis: 0.234)
``mrf:CORPUS``            :class:`MRFPrior`, 4-neighbourhood, ``lambda`` and ``psi = P(unequal) /
                          P(equal)`` of neighbour pairs in the corpus (Section 5.2.1)
``mrf8:CORPUS``           the same on the 8-neighbourhood
``patch3:CORPUS``         :class:`PatchTablePrior` over 3 x 3 tiles (Section 5.2.2), all configurations
``patch3_999:CORPUS``     the same truncated to the configurations carrying 99.9 % of the mass
``patch5:CORPUS``         5 x 5 tiles (sparse table of the configurations seen)
``border:CORPUS``         :class:`BorderPatchPrior`, a 3 x 3 patch given its 16 border cells (5.2.3)
``border1:CORPUS``        one cell given its 8 neighbours
========================  ==========================================================================

The tables were learned on the corpus's *training* plans only, with the buildings of the real logs
excluded (:data:`~ogm_ppl.datasets.floorplans.REAL_LOG_BUILDINGS`): evaluate on held-out plans or logs.

>>> prior_by_name("independent:houseexpo", (4, 5)).num_cells
20
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from ogm_ppl.priors.base import MapPrior

if TYPE_CHECKING:
    from ogm_ppl.priors.tables import PriorTables

__all__ = ["prior_by_name", "PRIOR_KINDS"]

PRIOR_KINDS = ("independent", "mrf", "mrf8", "patch3", "patch3_999", "patch5", "border", "border1")
DEFAULT_CORPUS = "houseexpo"


def _shape(shape) -> tuple[int, ...]:
    s = getattr(shape, "shape", shape)
    return tuple(int(v) for v in (s if np.ndim(s) else (s,)))


def prior_by_name(name: str, shape, tables: PriorTables | None = None) -> MapPrior:
    """The prior called ``name`` (module docstring) over a grid of ``shape`` (a tuple or a ``Grid``).

    Args:
        tables: a :class:`~ogm_ppl.priors.tables.PriorTables` to use instead of the shipped corpus.
    """
    from ogm_ppl.priors.border import BorderPatchPrior
    from ogm_ppl.priors.independent import IndependentPrior
    from ogm_ppl.priors.mrf import MRFPrior
    from ogm_ppl.priors.patch_table import PatchTablePrior
    from ogm_ppl.priors.tables import available_tables, tables_by_name

    if not isinstance(name, str) or not name:
        raise ValueError(f"a prior name is a non-empty string, got {name!r}")
    kind, _, corpus = name.partition(":")
    if kind not in PRIOR_KINDS:
        raise ValueError(f"unknown prior kind {kind!r} in {name!r}; kinds: {', '.join(PRIOR_KINDS)}")
    shape = _shape(shape)
    K = int(np.prod(shape))
    if kind == "independent" and not corpus:
        return IndependentPrior(0.5, K)  # the name alone is always the uniform prior
    if tables is None:
        corpus = corpus or DEFAULT_CORPUS
        if corpus not in available_tables():
            raise ValueError(f"no shipped tables for corpus {corpus!r}; shipped: {available_tables()}")
        tables = tables_by_name(corpus)
    lam = float(tables.lam)
    if kind == "independent":
        return IndependentPrior(lam, K)
    if kind in ("mrf", "mrf8"):
        conn = 4 if kind == "mrf" else 8
        lam_c, psi = tables.mrf_fit(conn)
        return MRFPrior(shape, order=1 if conn == 4 else 2, psi=min(1.0, psi), cell_prior=lam_c)
    if len(shape) != 2:
        raise ValueError(f"prior {name!r} is a 2D patch prior; the grid has shape {shape}")
    if kind in ("patch3", "patch3_999"):
        return PatchTablePrior(shape, codes=np.arange(512), counts=tables.counts3x3, patch=(3, 3),
                               mass=0.999 if kind == "patch3_999" else None)  # fmt: skip
    if kind == "patch5":
        return PatchTablePrior(shape, codes=tables.codes5x5, counts=tables.counts5x5, patch=(5, 5))
    if kind == "border":
        return BorderPatchPrior(shape, *tables.border_table().triples(), inner=(3, 3))
    return BorderPatchPrior(shape, *tables.border1_triples(), inner=(1, 1))
