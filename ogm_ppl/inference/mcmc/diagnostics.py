r"""Convergence diagnostics for map samplers: several chains, split R-hat, effective sample size, and the
KL divergence of running marginals to an exact posterior (Fig. 4.3).

R-hat is Pyro's (``pyro.ops.stats.split_gelman_rubin``); ESS is Pyro's estimator in linear memory with
Stan's bound for anti-correlated chains (:func:`effective_sample_size`). Both apply to the per-sweep
values of chosen cells (``RunningStats(trace_cells=...)``).
"""

from __future__ import annotations

import math
import multiprocessing
import pickle
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch
from pyro.ops.stats import autocovariance, split_gelman_rubin
from tqdm.auto import tqdm

from ogm_ppl.inference.mcmc.runner import RunningStats, run_gibbs
from ogm_ppl.metrics import kl_divergence

__all__ = ["ChainsResult", "run_chains", "split_rhat", "ess", "effective_sample_size", "kl_trace"]


def _per_cell(fn, traces) -> torch.Tensor:
    """Apply a Pyro statistic to the non-constant cells only: with pyro 1.9, one cell that never changes
    makes ``effective_sample_size`` NaN for *every* cell (and ``MCMC.summary`` shows NaN n_eff), and
    binary maps always have such cells (pinned, or far from any reading)."""
    x = torch.as_tensor(np.asarray(traces), dtype=torch.float64)
    flat = x.reshape(-1, x.shape[-1])
    varying = (flat != flat[:1]).any(0)
    out = torch.full((x.shape[-1],), float("nan"), dtype=torch.float64)
    if varying.any():
        out[varying] = fn(x[..., varying], chain_dim=0, sample_dim=1)
    return out


def effective_sample_size(x: torch.Tensor, chain_dim: int = 0, sample_dim: int = 1) -> torch.Tensor:
    """Pyro's ``effective_sample_size`` (Geyer's initial monotone sequence over chains, as in Stan) in
    linear memory: Pyro 1.9's cumulative minimum allocates ``(N/2)^2`` values per cell (30 GB for 30,000
    sweeps of 17 cells), ours is ``torch.cummin``. Chains ``x``: ``chains x draws x cells`` (dims
    ``chain_dim`` and ``sample_dim``). Anti-correlated chains (metropolised Gibbs flips a cell whose
    conditional is near 1/2 nearly every sweep) beat independent draws; as Stan does, the
    autocorrelation time is bounded below by ``1 / log10(C N)``, so the ESS is at most ``C N log10(C N)``
    (Pyro's comes out negative there).
    """
    x = torch.as_tensor(x, dtype=torch.float64).movedim((sample_dim, chain_dim), (0, 1))  # N x C x cells
    N, C = x.shape[0], x.shape[1]
    if N < 2:
        raise ValueError("ESS needs at least 2 draws per chain")
    gamma = autocovariance(x, dim=0)  # N x C x cells
    var_within = x.var(dim=0).mean(dim=0)
    var_est = (N - 1) / N * var_within
    if C > 1:
        var_est = var_est + x.mean(dim=0).var(dim=0)
    else:
        var_within = var_est
    rho = (var_est - var_within + gamma.mean(dim=1)) / var_est
    rho[0] = 1.0
    rho = rho if N % 2 == 0 else rho[:-1]
    pairs = rho.reshape((N // 2, 2) + rho.shape[1:]).sum(dim=1)
    tau = -1 + 2 * pairs[0]
    if len(pairs) > 1:
        tau = tau + 2 * torch.cummin(pairs[1:].clamp(min=0), dim=0).values.sum(dim=0)
    total = N * C
    return total / tau.clamp(min=1.0 / math.log10(max(total, 10)))


def split_rhat(traces: np.ndarray | torch.Tensor) -> torch.Tensor:
    """Split R-hat per traced cell from ``chains x sweeps x cells`` values (NaN for constant cells)."""
    return _per_cell(split_gelman_rubin, traces)


def ess(traces: np.ndarray | torch.Tensor) -> torch.Tensor:
    """Effective sample size per traced cell, over all chains (NaN for constant cells); see
    :func:`effective_sample_size`."""
    return _per_cell(effective_sample_size, traces)


@dataclass
class ChainsResult:
    stats: list[RunningStats]

    @property
    def marginals(self) -> torch.Tensor:
        """Marginals pooled over chains (``K``)."""
        return torch.stack([s.marginals for s in self.stats]).mean(0)

    def traces(self) -> np.ndarray:
        """``chains x sweeps x traced cells``."""
        return np.stack([s.trace() for s in self.stats])

    def rhat(self) -> torch.Tensor:
        return split_rhat(self.traces())

    def ess(self) -> torch.Tensor:
        return ess(self.traces())


_WORKER: dict = {}


def _init_worker(make_kernel) -> None:
    """Runs once per worker process: the kernel factory (and the model in it) crosses over once, not
    once per chain."""
    torch.set_num_threads(1)
    _WORKER["make_kernel"] = make_kernel


def _run_chain(num_sweeps, trace_cells, warmup, seed) -> dict:
    kernel = _WORKER["make_kernel"]()
    stats = RunningStats(kernel.model, trace_cells=trace_cells)
    run_gibbs(kernel, num_sweeps, stats, warmup=warmup, seed=seed, progress=False)
    return stats.state_dict()


def run_chains(
    make_kernel: Callable[[], Any],
    num_chains: int,
    num_sweeps: int,
    trace_cells: Sequence[int],
    warmup: int = 0,
    seed: int = 0,
    progress: bool = False,
    processes: int = 1,
    mp_context: str | None = None,
) -> ChainsResult:
    """Independent chains with seeds ``seed, seed + 1, ...``: one after another in this process
    (``processes=1``), or on ``processes`` worker processes (one chain per task). Chain ``c`` draws the
    same numbers either way, so the results are identical, serial or parallel.

    With ``processes > 1``, ``make_kernel`` must be picklable: a class or ``functools.partial``, e.g.
    ``partial(CellGibbs, model, update="metropolised")``, not a lambda; it is sent once to each worker.
    Workers start with ``mp_context``: ``"fork"`` where the platform has it (as ``pyro.infer.MCMC`` does;
    workers inherit the model and run torch on one thread), else ``"spawn"`` (each worker pays the imports
    and the model's transfer once: about 9 s for the 500 x 500 reference scene here). A sweep is
    memory-bound, so chains sharing a machine's memory bandwidth speed up less than the core count (4
    chains of 100 sweeps on that scene: 1.74x on 2 cores with fork, 1.07x with spawn;
    ``benchmarks/bench_mixing.py``).
    """
    if num_chains < 1:
        raise ValueError("num_chains must be >= 1")
    if processes < 1:
        raise ValueError("processes must be >= 1")
    trace_cells = [int(c) for c in trace_cells]
    if processes == 1 or num_chains == 1:
        out = []
        for c in range(num_chains):
            kernel = make_kernel()
            stats = RunningStats(kernel.model, trace_cells=trace_cells)
            run_gibbs(kernel, num_sweeps, stats, warmup=warmup, seed=seed + c, progress=progress)
            out.append(stats)
        return ChainsResult(out)
    try:
        pickle.dumps(make_kernel)
    except Exception as e:
        raise ValueError(
            "make_kernel must be picklable to run chains in processes (use a class or "
            f"functools.partial, not a lambda): {e}"
        ) from None
    if mp_context is None:
        mp_context = "fork" if "fork" in multiprocessing.get_all_start_methods() else "spawn"
    ctx = multiprocessing.get_context(mp_context)
    with ProcessPoolExecutor(
        max_workers=min(processes, num_chains), mp_context=ctx, initializer=_init_worker, initargs=(make_kernel,)
    ) as pool:
        futures = [pool.submit(_run_chain, num_sweeps, trace_cells, warmup, seed + c) for c in range(num_chains)]
        states = [f.result() for f in tqdm(futures, desc="chains", disable=not progress)]
    model = make_kernel().model
    out = []
    for state in states:
        stats = RunningStats(model, trace_cells=trace_cells)
        stats.load_state_dict(state)
        out.append(stats)
    return ChainsResult(out)


def kl_trace(
    kernel, exact_marginals: torch.Tensor, checkpoints: Sequence[int], seed: int = 0, eps: float = 1e-9
) -> torch.Tensor:
    """Summed cell KL ``D_KL(exact || running marginals)`` after each number of sweeps in
    ``checkpoints`` (Fig. 4.3); running marginals are clamped to ``[eps, 1 - eps]``."""
    checkpoints = sorted(int(c) for c in checkpoints)
    torch.manual_seed(seed)
    kernel.setup()
    params = kernel.initial_params
    acc = torch.zeros(kernel.model.num_cells, dtype=torch.float64)
    out = []
    for i in range(1, checkpoints[-1] + 1):
        params = kernel.sample(params)
        acc += kernel.model.full_map(params["m"])
        if i in checkpoints:
            out.append(float(kl_divergence(exact_marginals, (acc / i).clamp(eps, 1 - eps))))
    return torch.tensor(out, dtype=torch.float64)
