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


#: bytes a particle of the tracegraph or rws loss holds for each cell and each reading at the peak of a step
#: (measured, two steps on a 64 x 64 map: 43 a cell with the mean-field guide, 80 with the patch guide, 70 a
#: reading)
PARTICLE_BYTES = 96
#: the most ``steps x particles x (cells + readings)`` a fit may ask for (0.3 to 1.6 microseconds each measured)
MAX_PARTICLE_WORK = 1 << 36


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

    def check_size(self, problem: MapProblem) -> None:
        """Refuse (:class:`ParamError` on ``num_particles`` or ``steps``, before the model is built) a fit whose
        particles would not fit in the free memory (:data:`PARTICLE_BYTES` a cell and a reading each, with the
        ``tracegraph`` and ``rws`` losses: the exact ELBO draws none), or that would take more than
        :data:`MAX_PARTICLE_WORK` ``steps x particles x (cells + readings)``."""
        if self.loss == "exact":
            return
        from ogm_ppl._memory import check_fits, in_units

        K, R = problem.grid.num_cells, int(problem.scans.num_valid)
        per = PARTICLE_BYTES * (K + R)
        check_fits(
            self.num_particles * per,
            f"{self.num_particles:,} particles of {self.loss} (each {PARTICLE_BYTES} bytes a cell and a reading: "
            f"{K:,} cells + {R:,} readings, {in_units(per)} a particle)",
            "use fewer particles",
            error=lambda message: ParamError("num_particles", message),
        )
        work = self.steps * self.num_particles * (K + R)
        if work > MAX_PARTICLE_WORK:
            raise ParamError(
                "steps",
                f"{self.steps:,} steps x {self.num_particles:,} particles x ({K:,} cells + {R:,} readings) = "
                f"{work:.3g}, over the limit of 2^36 = {MAX_PARTICLE_WORK:.3g} (ogm_ppl.methods.variational."
                "MAX_PARTICLE_WORK: at 0.3 to 1.6 microseconds each, 6 hours or more); use fewer steps or particles",
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
