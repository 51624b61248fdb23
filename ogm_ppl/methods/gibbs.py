r"""``gibbs`` and ``metropolis``: MCMC over the full posterior ``p(m | z)`` (Chapter 4).

``gibbs``: single-cell Gibbs (:class:`~ogm_ppl.inference.mcmc.CellGibbs`, ``patch = 1``) or patch Gibbs
(:class:`~ogm_ppl.inference.mcmc.PatchGibbs`, Algorithm 1; Algorithm 2 with ``p_rand_patch``), heat-bath or
metropolised updates, or ``update = "thesis"``: the thesis's border update (Section 5.2.3), which draws
each tile of a table prior from its own table and ignores its neighbours' factors (not exact);
``warm_thesis = N`` starts an exact patch chain where N sweeps of that update end (a starting map only);
``cell_sweeps = true`` follows every patch sweep by a single-cell Gibbs sweep
(:class:`~ogm_ppl.inference.mcmc.KernelCycle`), which moves the cells that straddle a table prior's tiles.
``threads = N`` sweeps in chromatic tiles on ``N`` of numba's threads
(:class:`~ogm_ppl.inference.mcmc.ChromaticCellGibbs`, :class:`~ogm_ppl.inference.mcmc.ChromaticPatchGibbs`):
exact, and the chain does not depend on ``N``, but it is not the serial kernel's chain.
``metropolis``: single-cell Metropolis-Hastings (:class:`~ogm_ppl.inference.mcmc.MetropolisCell`) with
uniform or end-point proposals.
"""

from __future__ import annotations

from dataclasses import dataclass

from ogm_ppl.methods._model import check_patch_work, patch_arg
from ogm_ppl.methods._sampling import _WHY_SWEEPS, MAX_SWEEPS, SamplingParams, run_kernel
from ogm_ppl.methods.params import Bool, Choice, Float, Int, Optional, ParamError, Patch, param
from ogm_ppl.methods.problem import MapProblem, MapResult, RunContext
from ogm_ppl.methods.registry import register_method

__all__ = ["GibbsParams", "MetropolisParams", "gibbs", "metropolis"]

SCANS = ("systematic", "permutation", "random")


@dataclass(frozen=True)
class GibbsParams(SamplingParams):
    patch: object = param(1, Patch(), "1: CellGibbs; a larger patch: PatchGibbs")
    scan: str = param("systematic", Choice(*SCANS), "order of the cells / patches in a sweep")
    update: str = param(
        "gibbs",
        Choice("gibbs", "metropolised", "thesis"),
        "heat bath, metropolised, or (PatchGibbs, table priors) the thesis's border update of Sec. 5.2.3",
    )
    p_rand_patch: float = param(0.0, Float(0, 0.999), "PatchGibbs: probability of a random configuration (Alg. 2)")
    random_patch: str = param(
        "mh",
        Choice("mh", "thesis"),
        "PatchGibbs: random configurations accepted by MH or always (the thesis)",
    )
    offset: int = param(0, Int(lo=0), "PatchGibbs: column of the tiling's first patch")
    p_escape: float = param(
        0.2, Float(0, 1, lo_open=True), "PatchGibbs, backed-off tables: probability of the escape move"
    )
    warm_thesis: int = param(
        0,
        Int(lo=0, hi=MAX_SWEEPS, why=_WHY_SWEEPS),
        "PatchGibbs, table priors: sweeps of the thesis's border update from the starting map; the chain "
        "starts where they end (a starting map: not counted, not part of the chain)",
    )

    cell_sweeps: bool = param(
        False,
        Bool(),
        "PatchGibbs: a single-cell Gibbs sweep after every patch sweep (KernelCycle), exact; frees the cells a "
        "tile update of a table prior leaves frozen",
    )
    threads: int | None = param(
        None,
        Optional(Int(lo=1)),
        "sweep on this many of numba's threads (ChromaticCellGibbs / ChromaticPatchGibbs: chromatic tile sweeps, "
        "exact, priors with a compiled face; one chain whatever the number, not the serial kernel's)",
    )

    def sweeps_run(self) -> int:
        return self.burn_in + self.sweeps + self.warm_thesis

    def check(self) -> None:
        super().check()
        if self.cell_sweeps and (self.patch == 1 or self.update == "thesis"):
            raise ParamError(
                "cell_sweeps", "adds single-cell sweeps to an exact patch chain: use a patch and update gibbs"
            )
        if self.update == "thesis" and self.patch == 1:
            raise ParamError("update", "'thesis' is the border update of patch Gibbs: use a patch, e.g. [3, 3]")
        if self.threads is not None:
            from ogm_ppl.inference.mcmc.parallel import max_threads

            if self.threads > max_threads():
                raise ParamError("threads", f"at most numba's {max_threads()} threads (NUMBA_NUM_THREADS)")
            if self.patch != 1 and self.scan == "random":
                raise ParamError("scan", "chromatic patch sweeps order fixed patches: systematic or permutation")
        if self.warm_thesis and (self.patch == 1 or self.update == "thesis"):
            raise ParamError(
                "warm_thesis", "starts a patch chain of another update from the thesis's: use a patch and update gibbs"
            )


@register_method("gibbs", GibbsParams, stochastic=True, sampler=True)
def gibbs(params: GibbsParams, problem: MapProblem, ctx: RunContext) -> MapResult:
    """Gibbs sampling of the full posterior (Chapter 4): CellGibbs, or PatchGibbs for patches."""
    from ogm_ppl.inference.mcmc import (
        CellGibbs,
        ChromaticCellGibbs,
        ChromaticPatchGibbs,
        KernelCycle,
        PatchGibbs,
    )

    model = params.model(problem)
    parallel = {"threads": params.threads} if params.threads is not None else {}
    Cell = ChromaticCellGibbs if parallel else CellGibbs
    Patch_ = ChromaticPatchGibbs if parallel else PatchGibbs
    if params.patch == 1:
        kernel = Cell(
            model, scan=params.scan, update=params.update, init=params.init, delta=params.init_delta, **parallel
        )
        details: dict = {"kernel": type(kernel).__name__}
    else:
        passes = (params.burn_in + params.sweeps + params.warm_thesis) * params.chains
        check_patch_work(params.patch, problem.grid.ndim, problem.grid.num_cells, passes, False, "PatchGibbs")

        def patch_kernel(update: str, init) -> PatchGibbs:
            return Patch_(
                model,
                patch=patch_arg(params.patch),
                scan=params.scan,
                offset=params.offset,
                p_rand_patch=params.p_rand_patch,
                random_patch=params.random_patch,
                update=update,
                init=init,
                delta=params.init_delta,
                p_escape=params.p_escape,
                **parallel,
            )

        init = params.init
        if params.warm_thesis:
            init = _thesis_start(patch_kernel("thesis", params.init), params.warm_thesis, ctx.seed)
        kernel = patch_kernel(params.update, init)
        details = {"kernel": type(kernel).__name__, "patch": params.patch}
        if params.cell_sweeps:
            cells = Cell(model, scan=params.scan, update=params.update, **parallel)
            details["kernel"] = f"KernelCycle({type(kernel).__name__}, {type(cells).__name__})"
            kernel = KernelCycle([kernel, cells])
    if parallel:
        details["threads"] = params.threads
    return run_kernel(kernel, params, problem, ctx, details)


def _thesis_start(kernel, sweeps: int, seed: int):
    """The map after ``sweeps`` sweeps of ``kernel`` (the thesis's border update) from its starting map, drawn
    from a stream of its own (seeded by ``seed``): the ``warm_thesis`` start of a patch chain."""
    import numpy as np
    import torch

    from ogm_ppl.inference.mcmc import run_gibbs

    run_gibbs(kernel, 0, warmup=sweeps, seed=(int(seed) * 0x9E3779B1 + 0x7F4A7C15) % 2**63, progress=False)
    return torch.from_numpy(kernel.state.astype(np.float64))


@dataclass(frozen=True)
class MetropolisParams(SamplingParams):
    proposal: str = param(
        "uniform",
        Choice("uniform", "endpoint"),
        "cells proposed uniformly, or end-point cells endpoint_weight times as often",
    )
    endpoint_weight: float = param(4.0, Float(0, lo_open=True), "weight of cells holding a beam's end point")
    scan: str = param("random", Choice(*SCANS), "order of the proposed cells")

    def check(self) -> None:
        super().check()
        if self.proposal == "endpoint" and self.scan != "random":
            raise ParamError("scan", "the endpoint proposal draws cells at random: use scan = 'random'")


@register_method("metropolis", MetropolisParams, stochastic=True, sampler=True)
def metropolis(params: MetropolisParams, problem: MapProblem, ctx: RunContext) -> MapResult:
    """Single-cell Metropolis-Hastings flips (MetropolisCell: uniform or end-point proposals)."""
    from ogm_ppl.inference.mcmc import MetropolisCell

    kernel = MetropolisCell(
        params.model(problem),
        proposal=params.proposal,
        endpoint_weight=params.endpoint_weight,
        scan=params.scan,
        init=params.init,
        delta=params.init_delta,
    )
    return run_kernel(kernel, params, problem, ctx, {"kernel": "MetropolisCell"})
