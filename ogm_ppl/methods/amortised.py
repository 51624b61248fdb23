r"""``amortised``: the amortised guide's one-pass map (inference compilation).

``q(m_k = 1 | z) = sigmoid(g(x(z))_k)``, a network ``g`` of the evidence features ``x(z)``
(:mod:`ogm_ppl.inference.variational.amortised`), trained on draws from the model's joint; no iteration.
"""

from __future__ import annotations

from dataclasses import dataclass

from ogm_ppl.methods.params import Bool, GuideFile, param
from ogm_ppl.methods.problem import MapProblem, MapResult, RunContext
from ogm_ppl.methods.registry import register_method

__all__ = ["AmortisedParams", "amortised", "load_guide", "set_symmetrize"]


@dataclass(frozen=True)
class AmortisedParams:
    guide: str = param(
        "shipped",
        GuideFile(),
        "the trained guide: 'shipped', 'corpus:CORPUS' (learned on a corpus's plans) or a saved guide (.npz)",
    )
    symmetrize: bool = param(
        False,
        Bool(),
        "average the guide's logits over the 8 turns and flips of the grid (8 network passes; guides without "
        "tile-phase channels, e.g. the corpus guides)",
    )


def load_guide(name: str, model, noise_known: bool = True):
    """The guide ``name`` (``"shipped"``, ``"corpus:CORPUS"`` or a path) for ``model``, its sensor setting
    checked (:meth:`~ogm_ppl.inference.variational.AmortisedGuide.check_setting`; ``noise_known=False``: the
    model's range noise is a default, not the data's, and only the range is compared)."""
    from ogm_ppl.inference.variational.amortised import AmortisedGuide, corpus_guide, shipped_guide

    if name == "shipped":
        guide = shipped_guide(model)
    elif name.startswith("corpus:"):
        guide = corpus_guide(name.removeprefix("corpus:"), model)
    else:
        guide = AmortisedGuide.load(name, model)
    guide.check_setting(model, noise_known=noise_known)
    return guide


def set_symmetrize(guide, on: bool) -> None:
    """``guide.symmetrize = on``, a guide with tile-phase channels refused as the parameter ``symmetrize``."""
    try:
        guide.symmetrize = on
    except ValueError as e:
        raise ValueError(f"--param symmetrize: {e}") from None


@register_method("amortised", AmortisedParams)
def amortised(params: AmortisedParams, problem: MapProblem, ctx: RunContext) -> MapResult:
    """The amortised guide's one-pass map q(m_k = 1 | z) (a network of the evidence features)."""
    model = problem.model()
    guide = load_guide(params.guide, model, noise_known=problem.sigma_cells is not None)
    set_symmetrize(guide, params.symmetrize)
    q = guide.marginals(model).numpy()
    return MapResult(q, problem.rays.reached(), {"ray_cells": int(problem.rays.nnz), "trained_for": guide.trained_for})
