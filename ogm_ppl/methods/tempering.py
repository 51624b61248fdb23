r"""``tempering``: parallel tempering over the full posterior ``p(m | z)`` (Chapter 4 under the coupled
priors of Chapter 5).

One chain per rung of a geometric ladder ``beta_i = beta_min^{i / (n - 1)}`` on the tempered targets
``p~(m)^beta_p L(m)^beta_l`` (:mod:`~ogm_ppl.inference.mcmc.tempering`), each swept by single-cell or
patch Gibbs, with swaps between neighbouring rungs; the map is the marginals of the cold chain
(``beta = 1``: the posterior).
"""

from __future__ import annotations

from dataclasses import dataclass

from ogm_ppl.methods._model import patch_arg
from ogm_ppl.methods._sampling import SamplingParams, run_kernel
from ogm_ppl.methods.params import Choice, Float, Int, ParamError, Patch, param
from ogm_ppl.methods.problem import MapProblem, MapResult, RunContext
from ogm_ppl.methods.registry import register_method

__all__ = ["TemperingParams", "tempering"]


#: bytes a rung's kernel holds for each cell beside its likelihood table (measured on a 64 x 64 map: 58)
RUNG_BYTES_PER_CELL = 64


@dataclass(frozen=True)
class TemperingParams(SamplingParams):
    rungs: int = param(4, Int(lo=1), "rungs of the geometric ladder (1: the cold chain alone)")
    beta_min: float = param(0.3, Float(0, 1, lo_open=True, hi_open=True), "beta of the hottest rung")
    temper: str = param("both", Choice("both", "prior", "likelihood"), "the factor(s) raised to beta")
    swaps: str = param("even-odd", Choice("even-odd", "all", "random"), "swap moves after each sweep")
    patch: object = param(1, Patch(), "1: CellGibbs rungs; a larger patch: PatchGibbs rungs")
    scan: str = param("systematic", Choice("systematic", "permutation", "random"), "order within a sweep")
    update: str = param("gibbs", Choice("gibbs", "metropolised"), "heat bath or metropolised update")

    def maps_swept(self) -> int:
        return self.rungs

    def check_size(self, problem: MapProblem) -> None:
        """Refuse (:class:`ParamError` on ``rungs``) a ladder whose rungs would not fit in the free memory, before
        the model is built: each rung holds its own likelihood table (``8 R W`` bytes, ``R`` rays of at most ``W``
        cells, unless only the prior is tempered) and its kernel's state (:data:`RUNG_BYTES_PER_CELL` a cell);
        then the sampling limits of every run (:meth:`SamplingParams.check_size`)."""
        from ogm_ppl._memory import check_fits, in_units
        from ogm_ppl.raycast import ray_cast_size

        K = problem.grid.num_cells
        size = ray_cast_size(problem.grid, problem.scans)
        table = 0 if self.temper == "prior" else 8 * size.rays * (size.longest + 1)
        per_rung = table + RUNG_BYTES_PER_CELL * K
        tables = (
            f"a likelihood table of {size.rays:,} rays x {size.longest + 1:,} float64 ({in_units(table)}) and "
            if table
            else ""
        )
        check_fits(
            self.rungs * per_rung,
            f"{self.rungs:,} rungs of parallel tempering (each {tables}{RUNG_BYTES_PER_CELL} bytes a cell "
            f"for its kernel's state, {K:,} cells: {in_units(per_rung)} a rung)",
            "use fewer rungs (4 to 16 are usual)",
            error=lambda message: ParamError("rungs", message),
        )
        super().check_size(problem)


@register_method("tempering", TemperingParams, stochastic=True, sampler=True)
def tempering(params: TemperingParams, problem: MapProblem, ctx: RunContext) -> MapResult:
    """Parallel tempering of the full posterior: tempered Gibbs chains and swaps, the cold chain's map."""
    from ogm_ppl.inference.mcmc import ParallelTempering, geometric_ladder

    betas = geometric_ladder(params.rungs, params.beta_min)
    kernel = ParallelTempering(
        params.model(problem),
        betas,
        kernel="cell" if params.patch == 1 else "patch",
        patch=(3, 3) if params.patch == 1 else patch_arg(params.patch),
        temper=params.temper,
        swaps=params.swaps,
        scan=params.scan,
        update=params.update,
        init=params.init,
        delta=params.init_delta,
    )
    details = {"kernel": "ParallelTempering", "betas": list(betas), "patch": params.patch}
    result = run_kernel(kernel, params, problem, ctx, details)
    result.details["swap_rates"] = [None if r != r else float(r) for r in kernel.swap_rates()]
    return result
