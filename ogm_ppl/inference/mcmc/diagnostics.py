r"""Convergence diagnostics for map samplers: several chains, split R-hat, effective sample size, and the
KL divergence of running marginals to an exact posterior (Fig. 4.3).

R-hat is Pyro's (``pyro.ops.stats.split_gelman_rubin``); ESS is Pyro's estimator in linear memory with
Stan's bound for anti-correlated chains (:func:`effective_sample_size`). Both apply to the per-sweep
values of chosen cells (``RunningStats(trace_cells=...)``).
"""

from __future__ import annotations

import contextlib
import math
import multiprocessing
import pickle
from collections.abc import Callable, Mapping, Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch
from pyro.ops.stats import autocovariance, split_gelman_rubin

from ogm_ppl._rng import keeps_global_rng
from ogm_ppl.inference.mcmc.runner import RunningStats, run_gibbs
from ogm_ppl.metrics import kl_divergence
from ogm_ppl.progress import Progress

__all__ = [
    "STARTS",
    "ChainsResult",
    "default_start_method",
    "effective_sample_size",
    "ess",
    "kl_trace",
    "print_summary",
    "rhat_agreement",
    "run_chains",
    "run_from_starts",
    "split_rhat",
    "start_maps",
    "summary",
]


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


def _samples_of(mcmc_or_samples) -> dict[str, torch.Tensor]:
    if hasattr(mcmc_or_samples, "get_samples"):
        return mcmc_or_samples.get_samples(group_by_chain=True)
    return dict(mcmc_or_samples)


@contextlib.contextmanager
def _per_cell_pyro_ess():
    """Within the block, Pyro's ``stats.effective_sample_size`` is :func:`effective_sample_size` applied to the
    non-constant entries of each site (``chains x draws x event``): what :func:`summary` runs Pyro's summary
    with. Restored on leaving."""
    import pyro.ops.stats as pyro_stats

    def per_entry(value, chain_dim=0, sample_dim=1):
        v = torch.as_tensor(value).movedim((chain_dim, sample_dim), (0, 1))
        flat = v.reshape(v.shape[0], v.shape[1], -1)
        return _per_cell(effective_sample_size, flat).to(v.dtype).reshape(v.shape[2:])

    original = pyro_stats.effective_sample_size
    pyro_stats.effective_sample_size = per_entry
    try:
        yield
    finally:
        pyro_stats.effective_sample_size = original


def summary(mcmc_or_samples, prob: float = 0.9) -> dict[str, dict[str, torch.Tensor]]:
    """``MCMC.summary()``'s numbers (``pyro.infer.mcmc.util.summary``: mean, std, median, the ``prob``
    interval, ``n_eff``, ``r_hat`` per site, each of the site's event shape) for an ``MCMC`` or a dict of
    ``chains x draws x ...`` samples, with ``n_eff`` per cell by :func:`effective_sample_size`. Pyro's own
    is NaN for *every* cell of a site once one cell never changes (pyro 1.9), and a map always has such
    cells; here those cells alone get NaN (and ``r_hat`` is NaN for them too, as in Pyro). Pyro's estimator is
    swapped for ours during the call only (not thread-safe against Pyro summaries run meanwhile in other
    threads)."""
    from pyro.infer.mcmc.util import summary as pyro_summary

    with _per_cell_pyro_ess():
        return pyro_summary(_samples_of(mcmc_or_samples), prob=prob, group_by_chain=True)


def print_summary(mcmc_or_samples, prob: float = 0.9) -> None:
    """Print ``MCMC.summary()``'s table with the per-cell ``n_eff`` of :func:`summary`."""
    from pyro.infer.mcmc.util import print_summary as pyro_print_summary

    with _per_cell_pyro_ess():
        pyro_print_summary(_samples_of(mcmc_or_samples), prob=prob, group_by_chain=True)


@dataclass
class ChainsResult:
    """The statistics of each chain (``stats[c]``), and the names of their starts (:func:`run_from_starts`)."""

    stats: list[RunningStats]
    starts: list[str] | None = None

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


def default_start_method() -> str:
    """How :func:`run_chains` starts its worker processes unless told: ``"forkserver"`` where the platform has it
    (workers forked from a clean server process that has imported the library once), else ``"spawn"``. Never
    ``"fork"`` of the calling process: a process that has started thread pools (torch's, numba's, JAX's, as a
    notebook has) can crash in a forked copy."""
    return "forkserver" if "forkserver" in multiprocessing.get_all_start_methods() else "spawn"


def _init_worker(make_kernel) -> None:
    """Runs once per worker process: the kernel factory (and the model in it) crosses over once, not
    once per chain: inherited (fork) or as the bytes of a plain pickle."""
    torch.set_num_threads(1)
    _WORKER["make_kernel"] = pickle.loads(make_kernel) if isinstance(make_kernel, bytes) else make_kernel


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

    Every chain starts where ``make_kernel()``'s kernel starts: with the kernels' default ``init="ogm"``, all
    from the one thresholded-OGM map (as ``pyro.infer.MCMC(num_chains=k)`` does). Their R-hat then tells whether
    the seeds agree, not whether the chains have left that start: under a strongly coupled prior several
    chains can agree on one wrong mode (R-hat 1.000 with marginals off by nearly 1). To judge mixing, start
    chains far apart: :func:`run_from_starts` with :func:`start_maps` (thresholded OGM, all free, a prior
    draw) and :func:`rhat_agreement`.

    With ``processes > 1`` the workers start with ``mp_context``: by default :func:`default_start_method`
    (``"forkserver"``, else ``"spawn"``), for which ``make_kernel`` must be picklable (a class or
    ``functools.partial``, e.g. ``partial(CellGibbs, model, update="metropolised")``, not a lambda): it is sent
    once to each worker (its initializer), not once a chain, and a worker runs torch on one thread. ``"fork"``
    only when asked: workers inherit ``make_kernel`` (no copy, a lambda will do), but a forked copy of a process
    that has started thread pools (torch's, numba's, JAX's: a notebook) can crash. A script that runs chains in
    processes needs the ``if __name__ == "__main__":`` guard (the workers import the main module). Start-up:
    forkserver and spawn workers import the library and load the compiled kernels afresh (measured on 2
    busy cores: about 0.3 s for fork, 2-6 s for forkserver or spawn per pool, so use them for long chains), and
    a sweep is memory-bound, so chains sharing a machine's memory bandwidth speed up less than the core count (4
    chains of 100 sweeps on the 500 x 500 reference scene: 1.74x on 2 cores with fork, 1.07x with spawn, whose
    model transfer took about 9 s; ``benchmarks/bench_mixing.py``).
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
    mp_context = default_start_method() if mp_context is None else mp_context
    if mp_context not in multiprocessing.get_all_start_methods():
        raise ValueError(
            f"mp_context must be one of this platform's start methods {multiprocessing.get_all_start_methods()}, "
            f"got {mp_context!r}"
        )
    ctx = multiprocessing.get_context(mp_context)
    shipped: Callable[[], Any] | bytes = make_kernel
    if mp_context != "fork":
        # a plain pickle, made once: multiprocessing's own pickler would move the model's tensors into shared
        # memory, which leaves the NumPy views of them (the compiled kernels' ray index) pointing at freed memory
        try:
            shipped = pickle.dumps(make_kernel, protocol=pickle.HIGHEST_PROTOCOL)
        except Exception as e:
            raise ValueError(
                f"make_kernel must be picklable to run chains in {mp_context} processes (use a class or "
                f"functools.partial, not a lambda; or mp_context='fork'): {e}"
            ) from None
    if mp_context == "forkserver":  # the server imports the library once; each worker is a fork of it
        ctx.set_forkserver_preload([__name__])
    with ProcessPoolExecutor(
        max_workers=min(processes, num_chains), mp_context=ctx, initializer=_init_worker, initargs=(shipped,)
    ) as pool:
        futures = [pool.submit(_run_chain, num_sweeps, trace_cells, warmup, seed + c) for c in range(num_chains)]
        states = []
        with Progress(num_chains, "chains", unit="chain", enabled=progress, after=10.0) as bar:
            for f in futures:
                states.append(f.result())
                bar.update()
    model = make_kernel().model
    out = []
    for state in states:
        stats = RunningStats(model, trace_cells=trace_cells)
        stats.load_state_dict(state)
        out.append(stats)
    return ChainsResult(out)


@keeps_global_rng
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


#: the named starts of :func:`start_maps`
STARTS = ("ogm", "free", "occupied", "prior", "guide")


def start_maps(
    model, starts: Sequence[str] = ("ogm", "free", "prior"), seed: int = 0, delta="haehnel"
) -> dict[str, torch.Tensor]:
    """Dispersed starting maps, ``name -> K`` float64 0/1 map (pinned cells free), by name:

    * ``"ogm"`` — traditional OGM thresholded at the mean prior occupancy (Section 4.1.2; ``delta``);
    * ``"free"`` / ``"occupied"`` — every latent cell free / occupied;
    * ``"prior"`` — a draw from the prior (torch's generator seeded with ``seed``; the global state is
      restored afterwards);
    * ``"guide"`` — the MAP of the shipped amortised guide (``q(m_k = 1 | z) > 1/2``, Section 2.5), for a
      model the shipped guide fits.
    """
    from ogm_ppl.inference.mcmc.kernel import initial_map

    out: dict[str, torch.Tensor] = {}
    for name in starts:
        if name not in STARTS:
            raise ValueError(f"unknown start {name!r}; the starts are {STARTS}")
        if name == "prior":
            rng = torch.get_rng_state()
            try:
                torch.manual_seed(int(seed))
                m = initial_map(model, "prior")
            finally:
                torch.set_rng_state(rng)
        elif name == "guide":
            from ogm_ppl.inference.variational.amortised import guide_initial_map, shipped_guide

            m = initial_map(model, guide_initial_map(shipped_guide(model), model, "mode"))
        else:
            m = initial_map(model, name, delta)
        out[name] = m.to(torch.float64)
    return out


def run_from_starts(
    make_kernel: Callable[..., Any],
    starts: Mapping[str, torch.Tensor],
    num_sweeps: int,
    trace_cells: Sequence[int],
    warmup: int = 0,
    seed: int = 0,
    progress: bool = False,
) -> ChainsResult:
    """One chain from each start (``name -> K`` map, e.g. :func:`start_maps`), chain ``c`` built by
    ``make_kernel(init=starts[name])`` (e.g. ``functools.partial(PatchGibbs, model, (3, 3))`` or
    ``partial(ParallelTempering, model, betas)``) and run with seed ``seed + c``; ``warmup`` sweeps are
    not recorded. Returns the chains' statistics (traces of ``trace_cells``) with their start names."""
    if not starts:
        raise ValueError("run_from_starts needs at least one start")
    trace_cells = [int(c) for c in trace_cells]
    out = []
    for c, m in enumerate(starts.values()):
        kernel = make_kernel(init=m)
        stats = RunningStats(kernel.model, trace_cells=trace_cells)
        run_gibbs(kernel, num_sweeps, stats, warmup=warmup, seed=seed + c, progress=progress)
        out.append(stats)
    return ChainsResult(out, list(starts))


def rhat_agreement(traces, cells: Sequence[int] | np.ndarray | None = None, threshold: float = 1.05) -> dict:
    r"""Agreement of chains from different starts: split R-hat (:func:`split_rhat`) per cell of ``traces``
    (``chains x sweeps x traced cells``, or a :class:`ChainsResult`) over the positions ``cells`` of the
    traced cells (default: all), and the fraction below ``threshold``.

    Cells constant over every chain have no R-hat (NaN): the chains agree on them, but they say nothing
    about mixing. Returns ``cells`` (how many), ``varying`` (those with an R-hat), ``frozen_apart`` (R-hat
    ``inf``: each chain constant, not all at the same value), ``fraction_below`` (of the varying cells),
    ``fraction_below_all`` (constant cells counted as agreeing), ``rhat_median``, ``rhat_max`` and the
    per-cell ``rhat`` (``float64`` array).
    """
    x = traces.traces() if isinstance(traces, ChainsResult) else np.asarray(traces)
    if x.ndim != 3:
        raise ValueError(f"traces must be chains x sweeps x cells, got shape {x.shape}")
    if x.shape[0] < 2 or x.shape[1] < 4:
        raise ValueError(f"split R-hat needs at least 2 chains of 4 sweeps, got {x.shape[0]} of {x.shape[1]}")
    if not threshold > 1.0:
        raise ValueError(f"threshold must exceed 1, got {threshold}")
    if cells is not None:
        idx = np.asarray(cells, dtype=np.int64).reshape(-1)
        if idx.size and (idx.min() < 0 or idx.max() >= x.shape[2]):
            raise ValueError(f"cells must be positions in 0..{x.shape[2] - 1} of the traced cells")
        x = x[:, :, idx]
    n = x.shape[2]
    rhat = split_rhat(x).numpy() if n else np.zeros(0)
    ok = ~np.isnan(rhat)
    below = rhat[ok] < threshold
    return {
        "cells": int(n),
        "varying": int(ok.sum()),
        "frozen_apart": int(np.isinf(rhat).sum()),
        "fraction_below": float(below.mean()) if ok.any() else float("nan"),
        "fraction_below_all": float((below.sum() + (~ok).sum()) / n) if n else float("nan"),
        "rhat_median": float(np.median(rhat[ok])) if ok.any() else float("nan"),
        "rhat_max": float(rhat[ok].max()) if ok.any() else float("nan"),
        "threshold": float(threshold),
        "rhat": rhat,
    }
