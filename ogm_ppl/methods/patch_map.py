r"""``patch_map``: the online or offline patch map (Section 3.2).

Each patch's configurations are weighted by the posterior with the rest of the map held at a reference
(offline: the MAP map of :func:`~ogm_ppl.inference.exact.map_estimate`; online: a map built scan by scan),
and the cells' marginals read off the patch distributions; ``overlap``: a patch centred on every cell.
"""

from __future__ import annotations

from dataclasses import dataclass

from ogm_ppl.methods._model import ModelParams, check_patch_work, patch_arg
from ogm_ppl.methods.params import Bool, Choice, ParamError, Patch, param
from ogm_ppl.methods.problem import MapProblem, MapResult, RunContext
from ogm_ppl.methods.registry import register_method

__all__ = ["PatchMapParams", "patch_map"]


@dataclass(frozen=True)
class PatchMapParams(ModelParams):
    patch: object = param([3, 3], Patch(), "the patch shape")
    mode: str = param("offline", Choice("offline", "online"), "offline (against the MAP map) or online")
    overlap: bool = param(False, Bool(), "offline only: a patch centred on every cell")

    def check(self) -> None:
        super().check()
        if self.overlap and self.mode != "offline":
            raise ParamError("overlap", "only the offline patch map has an overlapping variant")


@register_method("patch_map", PatchMapParams, aliases={"patch": {"overlap": True}})
def patch_map(params: PatchMapParams, problem: MapProblem, ctx: RunContext) -> MapResult:
    """The patch map (Section 3.2): patch posteriors against a reference map, read as cell marginals."""
    from ogm_ppl.inference.patch_map import offline_patch_map, online_patch_map

    check_patch_work(params.patch, problem.grid.ndim, problem.grid.num_cells, 1, params.overlap, "the patch map")
    model = params.model(problem)
    # progress over the patches: a bar on a terminal, plain lines with the time left once past 10 s
    if params.mode == "offline":
        pm = offline_patch_map(model, patch_arg(params.patch), overlap=params.overlap, progress=ctx.progress)
    else:
        pm = online_patch_map(model, patch_arg(params.patch), progress=ctx.progress)
    details = {
        **params.model_details(problem, model),
        "reference": "MAP map" if params.mode == "offline" else "online",
    }
    return MapResult(pm.marginals.numpy(), problem.rays.reached(), details)
