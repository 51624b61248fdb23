r"""``vi``: variational inference of the map posterior with a Pyro guide.

``q`` is fitted by ``SVI`` (:func:`~ogm_ppl.inference.variational.fit_guide`) to the model's posterior:
reverse KL with score-function gradients (``loss = "tracegraph"``), importance-weighted wake-phi updates
fitting ``KL(p || q)`` (``"rws"``), or the ELBO in closed form (``"exact"``; an independent prior, and the
mean-field or first-hit guide). Guides: ``mean_field`` (``prod_k Bernoulli(sigmoid(phi_k))``), ``patch``
(a categorical over each non-overlapping patch's configurations, Chapter 3's family), ``first_hit``
(the exact 1D posterior's family on a common ray). The map is ``q(m_k = 1)``.
"""

from __future__ import annotations

from dataclasses import dataclass

from ogm_ppl.methods._model import ModelParams, patch_arg
from ogm_ppl.methods.params import Choice, Float, Int, ParamError, Patch, param
from ogm_ppl.methods.problem import MapProblem, MapResult, RunContext
from ogm_ppl.methods.registry import register_method

__all__ = ["VIParams", "vi"]


@dataclass(frozen=True)
class VIParams(ModelParams):
    guide: str = param("mean_field", Choice("mean_field", "patch", "first_hit"), "the guide's family")
    loss: str = param("exact", Choice("exact", "tracegraph", "rws"), "the objective (exact: closed-form ELBO)")
    steps: int = param(300, Int(lo=1), "SVI steps")
    lr: float = param(0.05, Float(0, lo_open=True), "Adam's learning rate")
    num_particles: int = param(64, Int(lo=1), "particles per step (tracegraph, rws)")
    patch: object = param(3, Patch(max_cells=12), "patch guide: the patch shape")
    p_rand: float = param(
        1e-3, Float(0, 1, hi_open=True), "sensor model's share of random readings (reverse KL needs > 0)"
    )

    def check(self) -> None:
        super().check()
        if self.loss == "exact" and self.guide == "patch":
            raise ParamError("loss", "the closed-form ELBO needs the mean_field or first_hit guide")
        if self.loss != "exact" and self.p_rand == 0:
            raise ParamError("p_rand", f"loss {self.loss!r} needs a likelihood without zeros: p_rand > 0")


@register_method("vi", VIParams, stochastic=True)
def vi(params: VIParams, problem: MapProblem, ctx: RunContext) -> MapResult:
    """Variational inference with a mean-field, patch or first-hit guide (Pyro SVI)."""
    from ogm_ppl.inference.variational import FirstHitGuide, MeanFieldGuide, PatchGuide, fit_guide

    model = params.model(problem)
    if params.loss == "exact" and model.prior.cell_log_odds() is None:
        raise ParamError("loss", f"the closed-form ELBO needs a prior with independent cells, not {params.prior!r}")
    if params.guide == "mean_field":
        guide = MeanFieldGuide(model)
    elif params.guide == "patch":
        guide = PatchGuide(model, patch_arg(params.patch))
    else:
        guide = FirstHitGuide(model)
    with ctx.progress_for(params.steps, "svi steps", "step") as bar:
        losses = fit_guide(
            model,
            guide,
            steps=params.steps,
            lr=params.lr,
            num_particles=params.num_particles,
            seed=ctx.seed,
            progress=bar,
            loss=params.loss,
        )
    details = {**params.model_details(problem, model), "guide": type(guide).__name__, "final_loss": losses[-1]}
    return MapResult(guide.marginals().numpy(), problem.rays.reached(), details)
