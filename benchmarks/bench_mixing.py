"""Effective samples per second and time to exact-posterior accuracy for every map sampler (Chapter 4).

Problems with exact answers: the thesis toy (K = 14 and 21 latent cells, the readings of Fig. 2.1), K = 200
with 30 readings of a wall at cell 100, and a 4 x 4 grid seen by three poses (brute force). For each
kernel and update rule: ESS per second (Pyro's ``effective_sample_size`` on the cells whose exact marginal
lies in [0.05, 0.95], median over those cells; anti-correlated chains are capped at N log10 N, as in
Stan, see ``ogm_ppl.inference.mcmc.diagnostics.ess``), and the wall-clock time until the summed cell KL of the
running marginals to the exact ones falls below 0.01 and 0.001. Then the 500 x 500 reference scene of
``bench_gibbs.py``: 4 chains, split R-hat (the finish line: < 1.01) and ESS/s on traced cells, serial and
on 2 worker processes (the parallel speed-up).

NumPyro's ``DiscreteGibbs`` (plain and ``modified=True``, Liu's metropolised Gibbs) runs as a peer on the
same problems when ``numpyro`` is installed (``pip install "ogm_ppl[peers]"``); its compile time is
reported apart. Ratios are ours / NumPyro's modified sampler. Writes ``out/bench/bench_mixing.json``.
``--quick``: fewer sweeps and no reference scene (a smoke run); ``--reference-only``: the reference scene alone.

Mixing under the strongly coupled learned priors (``--tempering-only``, about 3-4 min; also part of the full
run): a 48 x 48 window of a held-out HouseExpo plan (never used to learn a table) with sparse stop-and-scan
data as in ``experiments/heldout_priors.py`` (3 stops, 90 beams, 75-cell range, sigma 1 cell); under
``mrf:houseexpo``, ``border:houseexpo`` and the backed-off ``border_bo:houseexpo`` (untempered and ``@cal``),
3 x 3 patch Gibbs and parallel tempering over it
(``ogm_ppl.inference.mcmc.tempering``; 4 rungs, geometric to beta = 0.3, prior and likelihood tempered) and
the cycle of 3 x 3 patch Gibbs with single-cell Gibbs (``ogm_ppl.inference.mcmc.KernelCycle``), and that cycle
with 3 x 3 patches on the tilings shifted by one and two cells, both every sweep (``mixing_cycle(...,
shifted=True)``) or one drawn at random per sweep (``shifted="random"``, a ``KernelMixture``); under the
backed-off 1-given-8 prior ``border1_bo:houseexpo`` and the tempered ``mrf8:houseexpo@cal``, single-cell Gibbs
(with the same sweeps and with 10 times as many) and the cycle of single cells and 2 x 2 blocks. Each sampler
runs one chain from each of 3 starts (thresholded OGM, all free, a prior draw); reported: the fraction of the
unseen near-mapped cells (no ray reached them) whose split R-hat over the 3 chains is below 1.05, the
seconds, the swap rates, and the ratios against the plain sampler (the first row of each prior); and per prior
the cycle's milliseconds per sweep with its parts taking the map over unchecked against re-checking it, with the
share of a sweep spent outside the parts' own sweeps.
"""

from __future__ import annotations

import os

os.environ.setdefault("NUMBA_NUM_THREADS", "1")

import argparse
import math
import sys
import time
from functools import partial

import numpy as np
import torch

sys.path.insert(0, os.path.dirname(__file__))
from _common import write_json

from ogm_ppl import GaussianRange, Grid, OccupancyModel, Scans, raycast
from ogm_ppl.datasets import THESIS_TOY_READINGS, toy_1d
from ogm_ppl.inference.exact import brute_force, pose_constrained_1d
from ogm_ppl.inference.mcmc import (
    CellGibbs,
    MetropolisCell,
    ParallelTempering,
    PatchGibbs,
    geometric_ladder,
    mixing_cycle,
    rhat_agreement,
    run_chains,
    run_from_starts,
    start_maps,
)
from ogm_ppl.inference.mcmc.diagnostics import default_start_method
from ogm_ppl.inference.mcmc.diagnostics import ess as ess_of
from ogm_ppl.priors import IndependentPrior

torch.set_default_dtype(torch.float64)
UNCERTAIN = (0.05, 0.95)


# ----------------------------------------------------------------------------------------- problems
def toy(K: int):
    t = toy_1d(num_cells=K + 1, readings=THESIS_TOY_READINGS)
    model = OccupancyModel(t.grid, raycast(t.grid, t.scans), GaussianRange(3.0), IndependentPrior(0.5, K + 1))
    return model, pose_constrained_1d(model).marginals


def wall200():
    t = toy_1d(num_cells=201, wall=100, num_readings=30, sigma=3.0, seed=0)
    model = OccupancyModel(t.grid, raycast(t.grid, t.scans), GaussianRange(3.0), IndependentPrior(0.5, 201))
    return model, pose_constrained_1d(model).marginals


def grid4x4():
    grid = Grid((4, 4), resolution=1.0)
    scans = Scans(
        [[0.5, 0.5, 0.0], [0.5, 0.5, 0.7], [3.5, 3.5, math.pi], [3.5, 3.5, -2.0], [0.5, 3.5, -0.6]],
        [0.0],
        [[2.6], [3.3], [2.2], [1.3], [2.9]],
        max_range=4.0,
        over_range="max",
    )
    model = OccupancyModel(grid, raycast(grid, scans), GaussianRange(0.8), IndependentPrior(0.4, 16))
    return model, brute_force(model).marginals


PROBLEMS = {"toy K=14": partial(toy, 14), "toy K=21": partial(toy, 21), "wall K=200": wall200, "grid 4x4": grid4x4}


def kernels(model) -> dict:
    patch = 3 if model.grid.ndim == 1 else (2, 2)
    out = {}
    for update in ("gibbs", "metropolised"):
        for scan in ("systematic", "permutation", "random"):
            out[f"cell {update} {scan}"] = partial(CellGibbs, model, scan=scan, update=update, init="free")
    out["MetropolisCell uniform random"] = partial(MetropolisCell, model, init="free")
    for update in ("gibbs", "metropolised"):
        out[f"patch {patch} {update}"] = partial(PatchGibbs, model, patch, update=update, init="free")
    return out


# ----------------------------------------------------------------------------------------- measures
def kl_sum(p: np.ndarray, q: np.ndarray, eps: float = 1e-9) -> np.ndarray:
    """Summed cell KL(p || q) for each row of q."""
    q = np.clip(q, eps, 1 - eps)
    p = np.clip(p, 0.0, 1.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        a = np.where(p > 0, p * np.log(p / q), 0.0)
        b = np.where(p < 1, (1 - p) * np.log((1 - p) / (1 - q)), 0.0)
    return (a + b).sum(-1)


def measure(trace: np.ndarray, seconds: float, exact: np.ndarray, uncertain: np.ndarray) -> dict:
    """``trace``: sweeps x latent cells (0/1); ``seconds``: wall time of those sweeps."""
    n = len(trace)
    per_sweep = seconds / n
    ess = ess_of(trace[None, :, uncertain])
    ess_med = float(np.nanmedian(ess.numpy())) if uncertain.any() else float("nan")
    running = np.cumsum(trace, 0) / np.arange(1, n + 1)[:, None]
    checkpoints = np.unique(np.geomspace(1, n, 400).astype(int)) - 1
    kl = kl_sum(exact[None, :], running[checkpoints])
    out = {
        "sweeps": n,
        "ms_per_sweep": 1e3 * per_sweep,
        "ess_median": ess_med,
        "ess_per_sweep": ess_med / n,
        "ess_per_s": ess_med / seconds,
        "final_kl": float(kl[-1]),
    }
    for thr in (0.01, 0.001):
        hit = np.flatnonzero(kl < thr)
        # the first checkpoint after which the KL stays below the threshold
        stay = next((i for i in hit if (kl[i:] < thr).all()), None)
        out[f"s_to_kl_{thr}"] = None if stay is None else float((checkpoints[stay] + 1) * per_sweep)
    return out


def run_ours(make, num_sweeps: int, seed: int = 0) -> tuple[np.ndarray, float]:
    kernel = make()
    torch.manual_seed(seed)
    kernel.setup()
    params = kernel.initial_params
    for _ in range(20):  # compile and warm up
        params = kernel.sample(params)
    trace = np.empty((num_sweeps, len(kernel.model.latent)), np.uint8)
    t = time.perf_counter()
    for i in range(num_sweeps):
        params = kernel.sample(params)
        trace[i] = params["m"].numpy()
    return trace, time.perf_counter() - t


# ----------------------------------------------------------------------------------------- NumPyro peer
def numpyro_peer(model, num_samples: int, modified: bool, seed: int = 0):
    """NumPyro's DiscreteGibbs on the same model (cells Bernoulli, one factor per ray from our likelihood
    table), one sample = one sweep. Returns (trace, seconds without compilation, compile seconds)."""
    import jax
    import jax.numpy as jnp
    import numpyro
    import numpyro.distributions as ndist
    from numpyro.infer import MCMC, DiscreteGibbs

    r = model.rays
    R, K = r.num_rays, model.num_cells
    lengths = np.diff(r.offsets)
    Lmax = int(lengths.max())
    ray_cells = np.full((R, Lmax), K, np.int64)  # K: a dummy cell that is always free
    for i in range(R):
        ray_cells[i, : lengths[i]] = r.cells[r.offsets[i] : r.offsets[i + 1]]
    ll = jnp.asarray(model.loglik_table.numpy()[:, : Lmax + 1])
    latent = jnp.asarray(model.latent.numpy())
    probs = jnp.asarray(torch.sigmoid(model.prior.cell_log_odds()).numpy()[model.latent.numpy()])
    ray_cells_j, lengths_j, rows = jnp.asarray(ray_cells), jnp.asarray(lengths), jnp.arange(R)

    def np_model():
        with numpyro.plate("cells", len(latent)):
            m = numpyro.sample("m", ndist.Bernoulli(probs=probs))
        full = jnp.zeros(K + 1).at[latent].set(m)
        occ = full[ray_cells_j] > 0
        first = jnp.where(occ.any(1), jnp.argmax(occ, 1), lengths_j)
        numpyro.factor("z", ll[rows, first].sum())

    mcmc = MCMC(DiscreteGibbs(np_model, modified=modified), num_warmup=20, num_samples=num_samples, progress_bar=False)
    key = jax.random.PRNGKey(seed)
    t = time.perf_counter()
    mcmc.run(key)
    first = time.perf_counter() - t
    t = time.perf_counter()
    mcmc.run(jax.random.PRNGKey(seed + 1))  # same shapes: the compiled sampler is reused
    steady = time.perf_counter() - t
    trace = np.asarray(mcmc.get_samples()["m"]).astype(np.uint8)
    return trace, steady, max(first - steady, 0.0)


# ----------------------------------------------------------------------------------------- reference scene
def reference_scene(num_sweeps: int) -> dict:
    from bench_gibbs import build

    model = build(500, 100)
    # trace cells that move: those a 30-sweep pilot chain changed at least once (most cells of a sparse
    # scene are certain, and a constant cell has no R-hat)
    pilot = CellGibbs(model, update="metropolised")
    torch.manual_seed(123)
    pilot.setup()
    params, first, moved = pilot.initial_params, pilot.state.copy(), np.zeros(model.num_cells, bool)
    for _ in range(30):
        params = pilot.sample(params)
        moved |= pilot.state != first
    rng = np.random.default_rng(0)
    candidates = np.flatnonzero(moved)
    trace_cells = np.sort(rng.choice(candidates, min(300, len(candidates)), replace=False))
    res = {
        "K": model.num_cells,
        "rays": model.rays.num_rays,
        "chains": 4,
        "sweeps_per_chain": num_sweeps,
        "traced_cells": len(trace_cells),
    }
    # the library's default start method, spawn, and fork only where it is safe: a process that has started
    # JAX's threads (the NumPyro peer above) must not fork (a forked copy can crash)
    contexts = [default_start_method(), "spawn"] + ([] if "jax" in sys.modules else ["fork"])
    res["start_methods"] = contexts
    for update in ("gibbs", "metropolised"):
        make = partial(CellGibbs, model, scan="systematic", update=update)
        runs = [(1, None)] + [(2, c) for c in contexts] if update == "metropolised" else [(1, None)]
        for processes, ctx in runs:
            t = time.perf_counter()
            chains = run_chains(
                make, 4, num_sweeps, trace_cells, warmup=20, seed=0, processes=processes, mp_context=ctx
            )
            sec = time.perf_counter() - t
            rhat = chains.rhat().numpy()
            ess = chains.ess().numpy()
            ok = np.isfinite(rhat)
            row = {
                "seconds": sec,
                "ess_median": float(np.nanmedian(ess)),
                "ess_per_s": float(np.nanmedian(ess)) / sec,
                "rhat_max": float(np.nanmax(rhat)),
                "rhat_median": float(np.nanmedian(rhat)),
                "frac_rhat_below_1.01": float((rhat[ok] < 1.01).mean()),
                "varying_cells": int(ok.sum()),
            }
            key = f"{update}, {processes} process(es)" + (f", {ctx}" if processes > 1 else "")
            res[key] = row
            print(
                f"  reference scene {update:12s} processes={processes} {ctx or '':10s}: {sec:6.1f} s, ESS/s "
                f"{row['ess_per_s']:.1f}, "
                f"R-hat max {row['rhat_max']:.3f}, {row['frac_rhat_below_1.01']:.0%} of {ok.sum()} varying cells < 1.01"
            )
    for ctx in contexts:
        res[f"parallel speed-up (metropolised, {ctx})"] = (
            res["metropolised, 1 process(es)"]["seconds"] / res[f"metropolised, 2 process(es), {ctx}"]["seconds"]
        )
        print(
            f"  4 chains on 2 processes ({ctx}): {res[f'parallel speed-up (metropolised, {ctx})']:.2f}x "
            "the speed of one after another"
        )
    return res


# ----------------------------------------------------------------------------------------- coupled priors
TEMPER_PLAN = ("houseexpo", "9f3a3b4917610fcc335719b8ed600b87", (64, 44), 48)  # corpus, plan, window corner, size


def heldout_window():
    """The held-out window of :data:`TEMPER_PLAN` and its sparse stop-and-scan data: (grid, rays, unseen
    cell indices, sigma)."""
    from ogm_ppl.datasets.floorplans import heldout_plans, load_plan
    from ogm_ppl.datasets.stop_and_scan import stop_and_scan
    from ogm_ppl.metrics import near_mapped_mask

    corpus, name, (r0, c0), size = TEMPER_PLAN
    if name not in heldout_plans(corpus):
        raise RuntimeError(f"{name} is not a held-out {corpus} plan")
    plan = load_plan(corpus, name)
    truth = plan.occupancy[r0 : r0 + size, c0 : c0 + size]
    known = plan.known[r0 : r0 + size, c0 : c0 + size]
    grid = Grid(truth.shape, resolution=plan.resolution)
    sigma = 1.0
    data = stop_and_scan(truth, grid, num_poses=3, beams=90, max_range_cells=75.0, sigma_cells=sigma, seed=0)
    rays = raycast(grid, data.scans)
    reached = rays.reached().reshape(grid.shape)
    unseen = near_mapped_mask(reached, 10.0) & known & ~reached
    return grid, rays, np.flatnonzero(unseen.ravel()), sigma


#: the coupled priors compared: unsmoothed (zero-mass barriers no move crosses) and backed off, untempered and
#: tempered by the exponent fitted on validation plans (``@cal``)
COUPLED = ("mrf:houseexpo", "border:houseexpo", "border_bo:houseexpo", "border_bo:houseexpo@cal")
#: priors sampled by single-cell Gibbs in the calibration protocol, against the cycle of single cells and 2 x 2
#: blocks on two tilings offset by one cell
CELL_COUPLED = ("border1_bo:houseexpo", "mrf8:houseexpo@cal")
#: how many times the sweeps of plain single-cell Gibbs in its "same time" row
CELL_SAME_TIME = 10


def coupled_priors(
    num_sweeps: int = 200, warmup: int = 50, rungs: int = 4, beta_min: float = 0.3, seed: int = 0
) -> dict:
    """Plain 3 x 3 patch Gibbs vs parallel tempering vs the patch + cell cycle from 3 starts under the learned
    coupled priors (module docstring): R-hat agreement over the unseen cells, seconds, ratios."""
    from ogm_ppl.priors.named import prior_by_name

    grid, rays, unseen, sigma = heldout_window()
    betas = geometric_ladder(rungs, beta_min)
    res: dict = {
        "plan": TEMPER_PLAN[1],
        "window": [*TEMPER_PLAN[2], TEMPER_PLAN[3]],
        "rays": rays.num_rays,
        "unseen_cells": len(unseen),
        "sweeps": num_sweeps,
        "warmup": warmup,
        "betas": list(betas),
        "starts": ["ogm", "free", "prior"],
        "seed": seed,
    }
    print(f"coupled priors: {grid.shape} window, {rays.num_rays} rays, {len(unseen)} unseen cells, betas {betas}")
    res["cell_same_time"] = CELL_SAME_TIME
    for name in COUPLED + CELL_COUPLED:
        model = OccupancyModel(grid, rays, GaussianRange(sigma), prior_by_name(name, grid.shape))
        starts = start_maps(model, res["starts"], seed=seed)
        PatchGibbs(model, (3, 3)).sample(PatchGibbs(model, (3, 3)).initial_params)  # compile outside the timing
        if name in CELL_COUPLED:
            mixing_cycle(model).sample(mixing_cycle(model).initial_params)
            makers = {
                "cell Gibbs": (partial(CellGibbs, model), num_sweeps, warmup),
                "cell Gibbs, 10x sweeps": (
                    partial(CellGibbs, model),
                    CELL_SAME_TIME * num_sweeps,
                    CELL_SAME_TIME * warmup,
                ),
                "cells + 2 x 2 blocks (KernelCycle)": (partial(mixing_cycle, model), num_sweeps, warmup),
            }
        else:
            makers = {
                "patch Gibbs": (partial(PatchGibbs, model, (3, 3)), num_sweeps, warmup),
                "parallel tempering": (
                    partial(ParallelTempering, model, betas, kernel="patch", patch=(3, 3), temper="both"),
                    num_sweeps,
                    warmup,
                ),
                "patch Gibbs, same time": (partial(PatchGibbs, model, (3, 3)), rungs * num_sweeps, rungs * warmup),
                "patch + cell Gibbs (KernelCycle)": (partial(mixing_cycle, model, (3, 3)), num_sweeps, warmup),
                "+ shifted tilings, both a sweep": (
                    partial(mixing_cycle, model, (3, 3), shifted=True),
                    num_sweeps,
                    warmup,
                ),
                "+ shifted tilings, one a sweep": (
                    partial(mixing_cycle, model, (3, 3), shifted="random"),
                    num_sweeps,
                    warmup,
                ),
            }
        rows = {}
        for label, (make, n, w) in makers.items():
            kernels = []

            def tracked(init, make=make, kernels=kernels):
                k = make(init=init)
                kernels.append(k)
                return k

            t = time.perf_counter()
            chains = run_from_starts(tracked, starts, n, unseen, warmup=w, seed=seed)
            sec = time.perf_counter() - t
            agree = rhat_agreement(chains)
            row = {k: v for k, v in agree.items() if k != "rhat"}
            row["seconds"] = sec
            if isinstance(kernels[0], ParallelTempering):
                row["swap_rates"] = np.nanmean([k.swap_rates() for k in kernels], 0).tolist()
            rows[label] = row
        base = rows[next(iter(makers))]  # ratios against the plain sampler (the first row)
        for label, row in rows.items():
            row["fraction_vs_base"] = (
                row["fraction_below_all"] / base["fraction_below_all"] if base["fraction_below_all"] > 0 else None
            )
            row["seconds_vs_base"] = row["seconds"] / base["seconds"]
            swaps = f"  swap rates {np.round(row['swap_rates'], 2).tolist()}" if "swap_rates" in row else ""
            print(
                f"  {name:23s} {label:34s} {row['seconds']:6.1f} s ({row['seconds_vs_base']:.1f}x)  "
                f"R-hat < 1.05: {row['fraction_below_all']:.0%} of {row['cells']} unseen cells "
                f"({row['fraction_below']:.0%} of {row['varying']} varying, {row['frozen_apart']} frozen apart)"
                f"{swaps}"
            )
        res[name] = rows
        res[name]["cycle hand-over"] = hand_over(model, None if name in CELL_COUPLED else (3, 3))
    return res


def hand_over(model, patch, num_sweeps: int = 100, seed: int = 0) -> dict:
    """Milliseconds per sweep of :func:`mixing_cycle` whose parts take the map over unchecked (``_adopt_map``)
    against the same cycle whose parts re-check it (:meth:`set_state`'s path), same seed, and the share of each
    sweep spent outside the parts' own sweeps (the hand-over)."""
    out = {}
    for label, checked in (("checked", True), ("unchecked", False)):
        k = mixing_cycle(model, patch)
        inside = [0.0]
        for part in k.kernels:
            if checked:  # a kernel that extends _set_state gets the checked hand-over

                def checked_set_state(self, m, base=type(part)._set_state):
                    base(self, m)

                cls = type(part)
                part.__class__ = type(f"Checked{cls.__name__}", (cls,), {"_set_state": checked_set_state})
            sweep = part._sweep

            def timed(sweep=sweep, inside=inside):
                t = time.perf_counter()
                n = sweep()
                inside[0] += time.perf_counter() - t
                return n

            part._sweep = timed
        torch.manual_seed(seed)
        k.setup()
        k.sample(k.current_params())
        inside[0] = 0.0
        t = time.perf_counter()
        for _ in range(num_sweeps):
            k.sample(k.current_params())
        sec = time.perf_counter() - t
        out[f"{label}_ms_per_sweep"] = 1e3 * sec / num_sweeps
        out[f"{label}_hand_over_share"] = 1.0 - inside[0] / sec
    out["checked_vs_unchecked"] = out["checked_ms_per_sweep"] / out["unchecked_ms_per_sweep"]
    print(
        f"  {'':23s} {'cycle hand-over':34s} {out['unchecked_ms_per_sweep']:.2f} ms/sweep unchecked "
        f"({out['unchecked_hand_over_share']:.0%} outside the parts), {out['checked_ms_per_sweep']:.2f} checked "
        f"({out['checked_hand_over_share']:.0%}): x{out['checked_vs_unchecked']:.2f}"
    )
    return out


def main(quick: bool = False) -> dict:
    out: dict = {"problems": {}}
    try:
        import numpyro  # noqa: F401

        have_peer = True
    except ImportError:
        have_peer = False
        print("numpyro not installed: the NumPyro peer is skipped (pip install 'ogm_ppl[peers]')")
    for pname, build in PROBLEMS.items():
        model, exact = build()
        exact_l = exact.numpy()[model.latent.numpy()]
        uncertain = (exact_l > UNCERTAIN[0]) & (exact_l < UNCERTAIN[1])
        n = 2000 if quick else (30000 if len(model.latent) < 100 else 50000)
        rows = {}
        print(f"{pname}: {len(model.latent)} latent cells, {int(uncertain.sum())} uncertain, {n} sweeps")
        for kname, make in kernels(model).items():
            trace, sec = run_ours(make, n)
            rows[kname] = measure(trace, sec, exact_l, uncertain)
        if have_peer:
            n_peer = 500 if quick else (3000 if len(model.latent) < 100 else 1000)
            for modified in (False, True):
                trace, sec, compile_s = numpyro_peer(model, n_peer, modified)
                row = measure(trace, sec, exact_l, uncertain)
                row["compile_s"] = compile_s
                rows[f"NumPyro DiscreteGibbs{' modified' if modified else ''}"] = row
        peer = rows.get("NumPyro DiscreteGibbs modified")
        for kname, row in rows.items():
            if peer and peer["ess_per_s"] > 0:
                row["ess_per_s_vs_numpyro_modified"] = row["ess_per_s"] / peer["ess_per_s"]
            t1 = row["s_to_kl_0.01"]
            print(
                f"  {kname:34s} {row['ms_per_sweep']:8.3f} ms/sweep  ESS/sweep {row['ess_per_sweep']:5.2f}  "
                f"ESS/s {row['ess_per_s']:10.1f}  KL<0.01 in {'-' if t1 is None else f'{t1:.3g} s':>9s}"
                + (
                    f"  x{row['ess_per_s_vs_numpyro_modified']:.1f} vs NumPyro modified"
                    if "ess_per_s_vs_numpyro_modified" in row
                    else ""
                )
            )
        out["problems"][pname] = rows
    if not quick:
        out["reference_scene"] = reference_scene(100)
        out["coupled_priors"] = coupled_priors()
    return out


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--reference-only", action="store_true", help="only the 4-chain reference-scene part")
    ap.add_argument("--tempering-only", action="store_true", help="only the coupled-prior part (tempering, cycles)")
    ap.add_argument("--seed", type=int, default=0, help="seed of the coupled-prior part's prior start and chains")
    args = ap.parse_args()
    t0 = time.perf_counter()
    if args.tempering_only:
        res = {"coupled_priors": coupled_priors(seed=args.seed), "total_s": time.perf_counter() - t0}
        print(f"total {res['total_s']:.0f} s; wrote {write_json('bench_mixing_coupled_priors', res)}")
        raise SystemExit(0)
    if args.reference_only:
        res = {"reference_scene": reference_scene(100), "total_s": time.perf_counter() - t0}
        print(f"wrote {write_json('bench_mixing_reference_scene', res)}")
        raise SystemExit(0)
    res = main(args.quick)
    res["total_s"] = time.perf_counter() - t0
    print(f"total {res['total_s']:.0f} s; wrote {write_json('bench_mixing' + ('_quick' if args.quick else ''), res)}")
