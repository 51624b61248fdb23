"""Gibbs sweep speed and memory (Chapter 4).

One L = 1 sweep over a 500 x 500 map scanned by 100 poses x 720 beams (F = 75 cells); the thesis's
Matlab needed 10.3 s per sweep at this size, the target here is under 0.1 s on one core and at least 10x
a plain-Python implementation of the same sweep (``ogm_ppl.reference.gibbs_cell_sweep_reference``, timed
on a subset of cells and scaled). Also: patch sweeps (1D runs are not used in 2D: 3 x 3 and plus),
scaling of sweep time with K and with the number of readings, the index memory for 2.25 M cells and
200,000 rays (target < 2 GB), and peak RSS. The single-cell sweeps are also timed against the sweep before
the kept-sum rewrite (kept in ``sweep_before_after.py``), interleaved in this process after 20 warm-up
sweeps, with the floor of that pair-summing sweep (one pass over its pair records). Writes out/bench/bench_gibbs.json.
"""

from __future__ import annotations

import os

os.environ.setdefault("NUMBA_NUM_THREADS", "1")

import sys
import time

import numpy as np
import torch

sys.path.insert(0, os.path.dirname(__file__))
from _common import best_time, peak_rss_mb, sparse_scene, write_json
from sweep_before_after import floors, interleaved, report

from ogm_ppl import GaussianRange, OccupancyModel, raycast
from ogm_ppl.inference.mcmc.gibbs import CellGibbs, PatchGibbs
from ogm_ppl.priors import IndependentPrior
from ogm_ppl.reference import gibbs_cell_sweep_reference

torch.set_default_dtype(torch.float64)
RES, F, SIGMA = 0.05, 75, 3.0


def scene(n: int, poses: int, beams: int = 720, seed: int = 0):
    return sparse_scene(
        n, poses, walls=max(4, n * n // 6000), seed=seed, res=RES, max_range_cells=F, sigma_cells=SIGMA, beams=beams
    )


def build(n: int, poses: int, beams: int = 720, lam: float = 0.234):
    grid, scans = scene(n, poses, beams)
    rays = raycast(grid, scans)
    model = OccupancyModel(grid, rays, GaussianRange(SIGMA), IndependentPrior(lam, grid.num_cells))
    return model


def sweep_time(kernel, repeat=3, warmup=1) -> float:
    """Best ``sample`` time (s) of ``repeat`` sweeps after ``warmup`` sweeps from the thresholded OGM map."""
    torch.manual_seed(0)
    kernel.setup()
    params = kernel.current_params()
    state = {"p": params}

    def one():
        state["p"] = kernel.sample(state["p"])

    return best_time(one, repeat=repeat, warmup=warmup)


def index_bytes(model) -> int:
    r = model.rays
    idx = r.by_cell
    arrays = [
        r.offsets,
        r.cells,
        r.t_enter,
        r.z,
        r.is_max,
        r.endpoint_in_grid,
        r.range_cells,
        idx.offsets,
        idx.ray,
        idx.kappa,
    ]
    # + the cell kernels' state: a kept sum and two counts a cell (16 bytes), first and second hits a ray (16)
    return sum(a.nbytes for a in arrays) + model.loglik_table.numel() * 8 + 16 * model.num_cells + 16 * r.num_rays


def main() -> dict:
    t = time.perf_counter()
    model = build(500, 100)
    setup_s = time.perf_counter() - t
    R, K, nnz = model.rays.num_rays, model.num_cells, model.rays.nnz
    print(
        f"500x500 map, {R} rays ({model.rays.is_max.mean():.0%} max-range), {nnz / 1e6:.2f} M ray-cells; "
        f"set-up {setup_s:.2f} s"
    )
    res = {}
    kernels = [
        (f"cell{'' if u == 'gibbs' else ' metropolised'}, {s}", CellGibbs(model, scan=s, update=u))
        for u in ("gibbs", "metropolised")
        for s in ("systematic", "permutation", "random")
    ]
    kernels += [
        ("patch 3x3, systematic", PatchGibbs(model, (3, 3), scan="systematic")),
        ("patch plus, random", PatchGibbs(model, "plus", scan="random")),
    ]
    for name, kern in kernels:
        # single-cell sweeps in the steady state (20 sweeps on: the first from the OGM map move more cells)
        res[name] = sweep_time(kern, repeat=5, warmup=20) if "cell" in name else sweep_time(kern, repeat=1)
        print(f"  {name:<32} {res[name]:8.4f} s per sweep")
    print(
        f"targets: systematic < 20 ms: {res['cell, systematic'] * 1e3:.1f} ms; "
        f"random < 60 ms: {res['cell, random'] * 1e3:.1f} ms (permutation {res['cell, permutation'] * 1e3:.1f} ms)"
    )
    before_after = interleaved(model, repeat=7)
    floor = floors(model)
    report(before_after, floor)
    # plain Python reference on a subset of cells, scaled by the cell count
    k = CellGibbs(model, scan="systematic")
    torch.manual_seed(0)
    k.setup()
    m = k.state.copy()
    sub = model.latent.numpy()[:: max(1, K // 20000)]
    u = np.random.default_rng(0).random(len(sub))
    t = time.perf_counter()
    gibbs_cell_sweep_reference(model, m, sub, u, model.prior.cell_log_odds().numpy())
    ref_sub = time.perf_counter() - t
    ref_full = ref_sub * len(model.latent) / len(sub)
    ours = res["cell, systematic"]
    print(f"  plain Python sweep (est. from {len(sub)} cells): {ref_full:8.2f} s per sweep")
    print(
        f"L = 1 sweep: {ours * 1e3:.1f} ms; {10.3 / ours:.0f}x the thesis's 10.3 s; "
        f"{ref_full / ours:.0f}x plain Python; target < 0.1 s: {'met' if ours < 0.1 else 'NOT met'}"
    )

    scaling = []
    print("\nscaling (cell Gibbs, systematic):  K        rays     s/sweep")
    for n, poses in ((250, 100), (500, 100), (1000, 100), (500, 25), (500, 400)):
        mdl = build(n, poses)
        s = sweep_time(CellGibbs(mdl, scan="systematic"), repeat=2)
        scaling.append({"K": mdl.num_cells, "rays": mdl.rays.num_rays, "seconds": s})
        print(f"{'':36}{mdl.num_cells:>9,}{mdl.rays.num_rays:>10,}{s:>10.4f}")
        del mdl

    t = time.perf_counter()
    big = build(1500, 278)  # 2.25 M cells, 200,160 rays
    big_setup = time.perf_counter() - t
    nbytes = index_bytes(big)
    print(
        f"\n1500x1500 (2.25 M cells), {big.rays.num_rays:,} rays: index + likelihood tables "
        f"{nbytes / 2**20:.0f} MiB (target < 2048 MiB); set-up {big_setup:.1f} s"
    )
    big_sweep = sweep_time(CellGibbs(big, scan="systematic"), repeat=1)
    print(f"one L = 1 sweep of the 2.25 M-cell map: {big_sweep:.3f} s; peak RSS {peak_rss_mb():.0f} MiB")
    payload = {
        "map_500": {
            "cells": K,
            "rays": R,
            "ray_cells": nnz,
            "seconds_per_sweep": res,
            "python_reference_seconds_per_sweep": ref_full,
            "speedup_vs_python": ref_full / ours,
            "speedup_vs_thesis_matlab": 10.3 / ours,
            "before_after_interleaved": before_after,
            "floor_seconds": floor,
        },
        "scaling": scaling,
        "map_1500": {
            "cells": big.num_cells,
            "rays": big.rays.num_rays,
            "index_mib": nbytes / 2**20,
            "seconds_per_sweep": big_sweep,
            "setup_seconds": big_setup,
        },
        "peak_rss_mib": peak_rss_mb(),
    }
    print("wrote", write_json("bench_gibbs", payload))
    return payload


if __name__ == "__main__":
    main()
