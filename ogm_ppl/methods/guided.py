r"""``guided_gibbs``: Gibbs sweeps mixed with block proposals from the amortised guide.

Each sweep is, with probability ``p_guide``, a pass of independence Metropolis-Hastings moves that
propose a block of cells from ``q(m_B | z)`` and accept with
``min(1, p(m') p(z | m') q_B(m_B) / (p(m) p(z | m) q_B(m'_B)))``, else a sweep of the base kernel
(:class:`~ogm_ppl.inference.mcmc.guided.GuidedGibbs`); the exact posterior stays stationary.
"""

from __future__ import annotations

from dataclasses import dataclass

from ogm_ppl.methods._model import patch_arg
from ogm_ppl.methods._sampling import SamplingParams, run_kernel
from ogm_ppl.methods.amortised import load_guide
from ogm_ppl.methods.gibbs import SCANS
from ogm_ppl.methods.params import Block, Bool, Choice, Float, GuideFile, Patch, param
from ogm_ppl.methods.problem import MapProblem, MapResult, RunContext
from ogm_ppl.methods.registry import register_method

__all__ = ["GuidedGibbsParams", "guided_gibbs"]


@dataclass(frozen=True)
class GuidedGibbsParams(SamplingParams):
    guide: str = param(
        "shipped",
        GuideFile(),
        "the proposing guide: 'shipped', 'corpus:CORPUS' (learned on a corpus's plans) or a saved guide (.npz)",
    )
    block: object = param([6, 6], Block(), "proposal block: [h, w] windows of a tiling, or 'all'")
    p_guide: float = param(0.5, Float(0, 1), "probability that a sweep is a pass of guide moves")
    start: str = param(
        "guide",
        Choice("guide", "guide_sample", "base"),
        "start from the guide's mode, a draw from it, or the base kernel's init",
    )
    random_offset: bool = param(True, Bool(), "draw the tiling's offset at every pass")
    proposal: str = param(
        "bernoulli",
        Choice("bernoulli", "tiles"),
        "independent cells, or whole tiles of a table prior tilted by the guide",
    )
    patch: object = param(1, Patch(), "base kernel: 1 CellGibbs, a larger patch PatchGibbs")
    scan: str = param("systematic", Choice(*SCANS), "scan of the base kernel")


@register_method("guided_gibbs", GuidedGibbsParams, stochastic=True, sampler=True)
def guided_gibbs(params: GuidedGibbsParams, problem: MapProblem, ctx: RunContext) -> MapResult:
    """Gibbs sweeps mixed with block proposals from the amortised guide (data-driven MCMC)."""
    from ogm_ppl.inference.mcmc import CellGibbs, PatchGibbs
    from ogm_ppl.inference.mcmc.guided import GuidedGibbs

    model = params.model(problem)
    if params.patch == 1:
        base = CellGibbs(model, scan=params.scan, init=params.init, delta=params.init_delta)
    else:
        base = PatchGibbs(
            model, patch=patch_arg(params.patch), scan=params.scan, init=params.init, delta=params.init_delta
        )
    block = patch_arg(params.block)
    kernel = GuidedGibbs(
        base,
        load_guide(params.guide, model, noise_known=params.sigma_cells is not None or problem.sigma_cells is not None),
        block=block,
        p_guide=params.p_guide,
        init=params.start,
        random_offset=params.random_offset,
        proposal=params.proposal,
    )
    result = run_kernel(kernel, params, problem, ctx, {"kernel": "GuidedGibbs", "base": type(base).__name__})
    result.details["acceptance_rate"] = float(kernel.acceptance_rate)
    return result
