r"""The run of a sampling method: ``burn_in + sweeps`` sweeps of a map kernel under
:func:`~ogm_ppl.inference.mcmc.run_gibbs`, the marginals of the last ``sweeps`` as the map.

With a checkpoint folder (``ctx.checkpoint_dir``) the run checkpoints every ``checkpoint_every`` sweeps
and resumes from the checkpoint; it records the running marginals' scores (``ctx.score``) at ``record``
evenly spaced sweeps after burn-in (``trace.json``, kept across resumes), and ``ctx.stop_after`` stops it
after that many sweeps of this call with the checkpoint kept and no map. The caller removes the spent checkpoint
once it has stored the map. The records' ``seconds`` are the chain's sampling time across calls (the
checkpoint carries it); ``details["resumed_seconds"]`` is the part spent before this call.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from typing import Any

from ogm_ppl.io import atomic_write_text
from ogm_ppl.methods._model import ModelParams, check_patch_work
from ogm_ppl.methods.params import DeltaName, Int, ParamError, StartMap, param
from ogm_ppl.methods.problem import MapProblem, MapResult, RunContext

__all__ = ["INITS", "MAX_CELL_UPDATES", "MAX_SWEEPS", "SamplingParams", "run_kernel"]

INITS = ("ogm", "prior", "occupied", "free")

#: the most sweeps (burn-in or counted) a sampling run may ask for: a billion sweeps are days of sampling on the
#: smallest real map, and the running sums stay exact counts in float64 far beyond
MAX_SWEEPS = 10**9
#: the most single-cell updates a sampling run may ask for (``(burn-in + sweeps) x chains x maps swept x cells``):
#: at the 0.1 to 3 microseconds one costs (a 64 x 64 map, one core), 2^40 are 30 hours or more
MAX_CELL_UPDATES = 1 << 40
_WHY_SWEEPS = "ogm_ppl.methods._sampling.MAX_SWEEPS: days of sampling on the smallest real map"


@dataclass(frozen=True)
class SamplingParams(ModelParams):
    """The model's parameters and the length, chains, checkpoints and records of the run."""

    sweeps: int = param(100, Int(lo=1, hi=MAX_SWEEPS, why=_WHY_SWEEPS), "sweeps counted in the marginals")
    burn_in: int = param(0, Int(lo=0, hi=MAX_SWEEPS, why=_WHY_SWEEPS), "sweeps run before counting")
    chains: int = param(
        1,
        Int(lo=1),
        "independent chains, their marginals averaged (the command line and experiments run them; run() one)",
    )
    init: str = param(
        "ogm", StartMap(*INITS), "starting map (initial_map: thresholded OGM, a prior draw, a corpus guide's mode, ...)"
    )
    init_delta: str = param("haehnel", DeltaName(), "update term of the 'ogm' starting map")
    checkpoint_every: int = param(10, Int(lo=1), "sweeps between checkpoints (with a checkpoint folder)")
    record: int = param(5, Int(lo=0), "scores of the running marginals recorded after burn-in")

    def sweeps_run(self) -> int:
        """Sweeps of one chain, whatever counts them (burn-in and counted sweeps)."""
        return self.burn_in + self.sweeps

    def maps_swept(self) -> int:
        """Maps a sweep updates (one; a rung each for parallel tempering)."""
        return 1

    def check_size(self, problem: MapProblem) -> None:
        """Refuse (:class:`ParamError`, before any work) a run of more than :data:`MAX_CELL_UPDATES` single-cell
        updates, or a patch kernel enumerating more than
        :data:`~ogm_ppl.methods._model.MAX_PATCH_CONFIGURATIONS` configurations."""
        K = problem.grid.num_cells
        sweeps, copies = self.sweeps_run(), self.maps_swept()
        updates = sweeps * self.chains * copies * K
        if updates > MAX_CELL_UPDATES:
            rungs = f" x {copies:,} maps swept (rungs)" if copies > 1 else ""
            raise ParamError(
                "sweeps",
                f"{sweeps:,} sweeps (burn-in {self.burn_in:,} + {self.sweeps:,}) x {self.chains:,} chains{rungs} x "
                f"{K:,} cells = {updates:.3g} single-cell updates, over the limit of 2^40 = {MAX_CELL_UPDATES:.3g} "
                "(ogm_ppl.methods._sampling.MAX_CELL_UPDATES: at 0.1 to 3 microseconds an update, 30 hours or more); "
                "use fewer sweeps or chains, or a smaller map",
            )
        patch = getattr(self, "patch", 1)
        if patch != 1:
            what = f"{type(self).__name__.removesuffix('Params')}'s patch kernel"
            check_patch_work(patch, problem.grid.ndim, K, sweeps * self.chains * copies, False, what)


def _read_json(path):
    try:
        return json.loads(path.read_text())
    except (FileNotFoundError, json.JSONDecodeError, OSError):
        return None


def _ckpt_sweep(path) -> int:
    import numpy as np

    try:
        with np.load(path, allow_pickle=False) as z:
            return int(z["sweep"])
    except Exception:
        return 0


def run_kernel(kernel, params: SamplingParams, problem: MapProblem, ctx: RunContext, details: dict) -> MapResult:
    """Run ``kernel`` (any :class:`~ogm_ppl.inference.mcmc.kernel.MapKernel` of ``params.model(problem)``) for
    ``params.burn_in + params.sweeps`` sweeps and return the marginals of the last ``params.sweeps`` as the
    map (``observed``: the cells some ray reached; ``details``: the kernel's, the model's, the records).

    With ``ctx.checkpoint_dir`` it checkpoints every ``params.checkpoint_every`` sweeps and on Ctrl-C,
    resumes from the checkpoint (bit for bit), records ``ctx.score`` of the running marginals at
    ``params.record`` marks and stops after ``ctx.stop_after`` sweeps of this call (``probabilities`` then
    ``None``); progress as ``ctx.progress_for`` says. One chain, seeded ``ctx.seed``."""
    from ogm_ppl.inference.mcmc import RunningStats, run_gibbs

    model = kernel.model
    details = {**params.model_details(problem, model), **details}
    observed = problem.rays.reached()
    warm, n = params.burn_in, params.sweeps
    stats = RunningStats(model)
    if ctx.checkpoint_dir is None:
        with ctx.progress_for(warm + n, "gibbs sweeps", "sweep") as bar:
            r = run_gibbs(kernel, n, stats, warmup=warm, seed=ctx.seed, progress=bar)
        if r.interrupted:
            raise KeyboardInterrupt
        q = stats.marginals.numpy()
        if ctx.score is not None:
            details["trace"] = [{"sweep": r.sweeps, "samples": int(stats.n), "seconds": r.seconds, **ctx.score(q)}]
        return MapResult(q, observed, details)

    folder = ctx.checkpoint_dir
    folder.mkdir(parents=True, exist_ok=True)
    ckpt, trace_path = folder / "gibbs.npz", folder / "trace.json"
    if not ctx.resume:
        ckpt.unlink(missing_ok=True)
        trace_path.unlink(missing_ok=True)
    trace = []
    if ckpt.exists():
        trace = (_read_json(trace_path) or {}).get("trace", [])
    elif trace_path.exists():
        trace_path.unlink()
    start = _ckpt_sweep(ckpt) if ckpt.exists() else 0
    total = warm + n
    k = min(params.record, n)  # more marks than counted sweeps are the same marks: one a sweep
    marks = sorted({warm + math.ceil(i * n / k) for i in range(1, k + 1)} | {total}) if k else [total]
    if start > total:  # a longer run's checkpoint (fewer sweeps asked for since): a chain cannot go back
        ckpt.unlink()
        start, trace = 0, []
    trace = [r for r in trace if r["sweep"] <= start and r["sweep"] in marks]  # records of this run's schedule
    done, before = start, None
    budget = ctx.stop_after
    details.update(resumed_from_sweep=start)
    run_kw: dict[str, Any] = {
        "warmup": warm,
        "seed": ctx.seed,
        "checkpoint": ckpt,
        "checkpoint_every": params.checkpoint_every,
    }
    # one progress for the chain's calls (one a mark): a bar on a terminal, plain lines past 10 s elsewhere
    with ctx.progress_for(total, "gibbs sweeps", "sweep", initial=start) as bar:
        for mark in marks:
            if mark <= done:
                continue
            step = mark - done
            if budget is not None:
                step = min(step, budget)
            r = run_gibbs(kernel, n, stats, **run_kw, progress=bar, stop_after=step)
            done, seconds = r.sweeps, r.seconds_total  # the chain's sampling time, earlier calls' included
            if before is None:
                before = r.seconds_total - r.seconds
                details["resumed_seconds"] = before
            if budget is not None:
                budget -= step
            if done == mark:
                rec = {"sweep": done, "samples": int(stats.n), "seconds": seconds}
                if stats.n and ctx.score is not None:
                    rec.update(ctx.score(stats.marginals.numpy()))
                trace.append(rec)
                text = json.dumps({"trace": trace}, indent=1, sort_keys=True, allow_nan=True)
                atomic_write_text(trace_path, text)
            elif budget is None or budget > 0:
                raise KeyboardInterrupt  # interrupted (SIGINT): the checkpoint is kept for a resume
            if budget is not None and budget <= 0 and done < total:
                return MapResult(None, observed, {**details, "trace": trace, "sweeps_total": done})
    if stats.n == 0:  # every mark was reached before (killed after the last checkpoint): load it
        r = run_gibbs(kernel, n, stats, **run_kw, progress=False)
        done = r.sweeps
        details["resumed_seconds"] = r.seconds_total
    return MapResult(stats.marginals.numpy(), observed, {**details, "trace": trace, "sweeps_total": done})
