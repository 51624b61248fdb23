"""Table 5.1 analogue: time per map sample with uniform, data-driven and border priors (Chapter 5).

The simple 2D example scaled to the thesis's size (K = 64,000 cells: our 64 x 64 map stretched to
200 x 320, the same three poses, 720 beams each, sigma = 3 cells). One map sample is one systematic sweep
of K / L patch updates. Priors: uniform (independent 0.5; L = 9 weighs all 2^9 configurations, L = 25 is
refused), data-driven (a patch table of the L-cell windows, truncated to 99.9% of the mass as in the
thesis; L = 1 is the 1 x 1 table, i.e. the learned cell prior) and border (p(patch | border): one cell
given its 8 neighbours, 3 x 3 given 16 border cells, and 5 x 5 given 24, which the thesis did not
compute). Tables are counted here from the example's own ground truth with its 8 flips/rotations (the
learned corpus tables arrive separately). Also: a 500 x 500 / 72,000-ray single-cell sweep with the MRF
prior and the pattern fields (``field`` / ``field2``) next to the independent prior (target: within
1.5x), the same with 3 x 3 patch sweeps (the fields against the independent prior's), and the border
prior with 3 x 3 patches at the
size of the thesis's Intel Lab experiment 1 (a 1500 x 1500 map, about 82,000 rays; 1518 s per sample in
the thesis) on a simulated walled map. Writes out/bench/bench_priors.json.

``--quick``: a smaller Table 5.1 map (100 x 160) and a 500 x 500 Intel-like map whose time is extrapolated
to 1500 x 1500 (labelled as such), for iterating on a busy machine. ``--overhead``: only the 500 x 500
single-cell and 3 x 3 patch sweep comparison (independent / MRF / pattern fields), to
out/bench/bench_priors_overhead.json.
"""

from __future__ import annotations

import os

os.environ.setdefault("NUMBA_NUM_THREADS", "1")

import sys
import time

import numpy as np
import torch

sys.path.insert(0, os.path.dirname(__file__))
from _common import best_time, sparse_scene, write_json

from ogm_ppl import GaussianRange, Grid, OccupancyModel, raycast
from ogm_ppl.datasets import simulate_scans
from ogm_ppl.datasets.simple2d import _truth
from ogm_ppl.inference.mcmc.gibbs import CellGibbs, PatchGibbs
from ogm_ppl.priors import BorderPatchPrior, IndependentPrior, MRFPrior, PatchTablePrior, prior_by_name

torch.set_default_dtype(torch.float64)
THESIS = {  # Table 5.1, Matlab seconds per map sample (None: intractable / not computed)
    1: {"uniform": 4.4, "data-driven": 5.1, "border": 6.6},
    9: {"uniform": 38.3, "data-driven": 23.9, "border": 2.7},
    25: {"uniform": None, "data-driven": 124.9, "border": None},
}


def scaled_example(rows=200, cols=320, seed=0):
    """The simple 2D example stretched to ``rows x cols`` cells, same three poses (scaled)."""
    small = _truth()
    ri = (np.arange(rows) * small.shape[0]) // rows
    ci = (np.arange(cols) * small.shape[1]) // cols
    truth = small[ri][:, ci]
    res = 0.05
    grid = Grid(truth.shape, resolution=res)
    sr, sc = rows / small.shape[0], cols / small.shape[1]
    poses = np.array([[8.5 * sc, 30.5 * sr, 0.0], [22.5 * sc, 8.5 * sr, 0.0], [40.5 * sc, 14.5 * sr, 0.0]])
    poses[:, :2] *= res
    for p in poses:  # poses on free cells
        r, c = int(p[1] / res), int(p[0] / res)
        assert not truth[r, c]
    angles = np.arange(720) * (2 * np.pi / 720)
    scans = simulate_scans(grid, truth, poses, angles, 40.0 * max(sr, sc) * res, 3.0, seed)
    return grid, truth, scans


def window_codes(truth: np.ndarray, n: int) -> np.ndarray:
    """Codes (bit i = cell i, row-major) of all n x n windows of the map and its 8 flips/rotations."""
    out = []
    for k in range(4):
        for flip in (False, True):
            t = np.rot90(truth, k)
            t = np.fliplr(t) if flip else t
            w = np.lib.stride_tricks.sliding_window_view(t.astype(np.int64), (n, n)).reshape(-1, n * n)
            out.append((w << np.arange(n * n, dtype=np.int64)).sum(1))
    return np.concatenate(out)


def fast_window_codes(truth: np.ndarray, n: int) -> np.ndarray:
    """Codes of all ``n x n`` windows of ``truth`` (no flips), by shifted slices: no ``n^2``-wide copy."""
    t = truth.astype(np.int64)
    R, C = t.shape[0] - n + 1, t.shape[1] - n + 1
    code = np.zeros((R, C), np.int64)
    for i in range(n * n):
        code |= t[i // n : i // n + R, i % n : i % n + C] << i
    return code.ravel()


def border_table(truth: np.ndarray, n: int):
    """(border, inner, count) of the ``(n + 2)^2`` windows of ``truth``: inner row-major, border the ring."""
    full, cnt = np.unique(fast_window_codes(truth, n + 2), return_counts=True)
    N = n + 2
    pos = [(r, c) for r in range(N) for c in range(N)]
    inner_pos = [i for i, (r, c) in enumerate(pos) if 0 < r < N - 1 and 0 < c < N - 1]
    ring_pos = [i for i, (r, c) in enumerate(pos) if not (0 < r < N - 1 and 0 < c < N - 1)]
    bits = (full[:, None] >> np.arange(N * N)) & 1
    return (
        (bits[:, ring_pos] << np.arange(len(ring_pos))).sum(1),
        (bits[:, inner_pos] << np.arange(len(inner_pos))).sum(1),
        cnt,
    )


def walled_map(n: int, seed: int = 0) -> np.ndarray:
    """An ``n x n`` indoor-like map: outer walls and a grid of rooms (walls 1 cell thick) with doorways."""
    rng = np.random.default_rng(seed)
    truth = np.zeros((n, n), dtype=bool)
    truth[0, :] = truth[-1, :] = truth[:, 0] = truth[:, -1] = True
    room = 60
    for x in range(room, n - 1, room):
        truth[x, :] = True
        truth[:, x] = True
    for x in range(room, n - 1, room):  # doorways in every wall segment
        for y in range(0, n - room, room):
            d = y + int(rng.integers(8, room - 16))
            truth[x, d : d + 8] = False
            d = y + int(rng.integers(8, room - 16))
            truth[d : d + 8, x] = False
    return truth


def intel_size(n: int = 1500, poses: int = 455, beams: int = 180, max_range_cells: int = 150) -> dict:
    """Border prior, 3 x 3 patches, on an ``n x n`` walled map scanned with ``poses x beams`` rays (the
    thesis's Intel Lab experiment 1: 1500 x 1500 cells, about 82,000 rays, 1518 s per map sample)."""
    t0 = time.perf_counter()
    truth = walled_map(n)
    res = 0.05
    grid = Grid(truth.shape, resolution=res)
    rng = np.random.default_rng(1)
    free = np.argwhere(~truth)
    pick = free[rng.choice(len(free), poses, replace=False)]
    xy = np.c_[(pick[:, 1] + 0.5) * res, (pick[:, 0] + 0.5) * res, rng.uniform(-np.pi, np.pi, poses)]
    angles = np.linspace(-np.pi / 2, np.pi / 2, beams)  # a 180 degree scanner, as in the Intel data
    scans = simulate_scans(grid, truth, xy, angles, max_range_cells * res, 3.0, 0)
    rays = raycast(grid, scans)
    prior = BorderPatchPrior(grid.shape, *border_table(truth, 3), inner=(3, 3))
    model = OccupancyModel(grid, rays, GaussianRange(3.0), prior)
    kern = PatchGibbs(model, (3, 3), p_rand_patch=0.001)
    setup = time.perf_counter() - t0
    s = sweep_seconds(kern, repeat=2)
    out = {
        "cells": grid.num_cells,
        "rays": rays.num_rays,
        "seconds": s,
        "setup_seconds": setup,
        "thesis_seconds": 1518.0,
    }
    print(
        f"\nIntel-size border prior, L = 9: {n} x {n} = {grid.num_cells:,} cells, {rays.num_rays:,} rays: "
        f"{s:.3f} s per map sample (set-up {setup:.1f} s; thesis 1518 s)"
    )
    return out


def priors_for(shape, truth):
    out = {}
    for L, n in ((1, 1), (9, 3), (25, 5)):
        codes, counts = np.unique(window_codes(truth, n), return_counts=True)
        out[("data-driven", L)] = PatchTablePrior(shape, codes, counts, patch=(n, n), mass=0.999 if L > 1 else None)
        w = np.unique(window_codes(truth, n + 2), return_counts=True)
        full, cnt = w
        # split each (n + 2)^2 window code into inner (row-major) and border (ring, row-major) codes
        N = n + 2
        pos = [(r, c) for r in range(N) for c in range(N)]
        inner_pos = [i for i, (r, c) in enumerate(pos) if 0 < r < N - 1 and 0 < c < N - 1]
        ring_pos = [i for i, (r, c) in enumerate(pos) if not (0 < r < N - 1 and 0 < c < N - 1)]
        bits = (full[:, None] >> np.arange(N * N)) & 1
        inner = (bits[:, inner_pos] << np.arange(len(inner_pos))).sum(1)
        border = (bits[:, ring_pos] << np.arange(len(ring_pos))).sum(1)
        out[("border", L)] = BorderPatchPrior(shape, border, inner, cnt, inner=(n, n))
    return out


def sweep_seconds(kernel, repeat=3) -> float:
    torch.manual_seed(0)
    kernel.setup()
    state = {"p": kernel.current_params()}

    def one():
        state["p"] = kernel.sample(state["p"])

    return best_time(one, repeat=repeat, warmup=1)


def table_5_1(rows: int = 200, cols: int = 320) -> dict:
    t0 = time.perf_counter()
    grid, truth, scans = scaled_example(rows, cols)
    rays = raycast(grid, scans)
    sensor = GaussianRange(3.0)
    priors = priors_for(grid.shape, truth)
    priors.update({("uniform", L): IndependentPrior(0.5, grid.num_cells) for L in (1, 9, 25)})
    print(
        f"simple 2D example at {grid.shape[0]} x {grid.shape[1]} = {grid.num_cells:,} cells, "
        f"{rays.num_rays:,} rays; set-up {time.perf_counter() - t0:.1f} s"
    )
    for L, n in ((9, 3), (25, 5)):
        p, b = priors[("data-driven", L)], priors[("border", L)]
        print(
            f"  {n}x{n}: table keeps {p.num_configurations} configurations (99.9% of the mass); border table "
            f"{b.num_borders} borders, at most {b.max_per_border} patches per border"
        )
    rows = {}
    print(f"\n{'':8}{'prior':<13}{'ours [s]':>10}{'thesis [s]':>12}{'thesis/ours':>13}")
    for L, patch in ((1, None), (9, (3, 3)), (25, (5, 5))):
        for name in ("uniform", "data-driven", "border"):
            model = OccupancyModel(grid, rays, sensor, priors[(name, L)])
            thesis = THESIS[L][name]
            try:
                kern = CellGibbs(model) if patch is None else PatchGibbs(model, patch, p_rand_patch=0.001)
                s = sweep_seconds(kern, repeat=3 if L < 25 or name != "uniform" else 1)
            except ValueError as e:
                s = None
                print(f"  L={L:<4}{name:<13}{'refused':>10}{thesis or '-':>12}   ({str(e)[:60]}...)")
            if s is not None:
                ratio = f"{thesis / s:,.0f}x" if thesis else "-"
                print(f"  L={L:<4}{name:<13}{s:>10.4f}{thesis or '-':>12}{ratio:>13}")
            rows[f"L={L}/{name}"] = {
                "seconds": s,
                "thesis_seconds": thesis,
                "speedup_vs_thesis": (thesis / s) if (s and thesis) else None,
            }
    r9 = [rows[f"L=9/{n}"]["seconds"] for n in ("border", "data-driven", "uniform")]
    order_ok = r9[0] < r9[1] < r9[2]
    speed_ok = all(v["speedup_vs_thesis"] >= 100 for v in rows.values() if v["speedup_vs_thesis"] is not None)
    print(f"thesis ordering at L = 9 (border < data-driven < uniform): {'holds' if order_ok else 'DOES NOT hold'}")
    print(f"every time at least 100x below the thesis's: {'yes' if speed_ok else 'NO'}")
    return {
        "cells": grid.num_cells,
        "rays": rays.num_rays,
        "rows": rows,
        "ordering_at_L9_holds": order_ok,
        "all_100x_faster": speed_ok,
    }


def backoff_vs_sparse(rows: int = 200, cols: int = 320) -> dict:
    """Border prior, L = 9, on the Table 5.1 scene: the sparse table next to its backed-off version
    (Witten-Bell towards the smoothed 3 x 3 table, ``kappa`` of the houseexpo fit), same tables, same
    kernel (``p_rand_patch = 0.001``), for a few escape probabilities (target: within 2x)."""
    from ogm_ppl.priors.backoff import BackoffBorderPrior, load_backoff_params, witten_bell
    from ogm_ppl.priors.backoff import independent_table as ind

    grid, truth, scans = scaled_example(rows, cols)
    rays = raycast(grid, scans)
    triples = border_table(truth, 3)
    hp = load_backoff_params("houseexpo")
    c3 = np.bincount(window_codes(truth, 3), minlength=512)
    back = witten_bell(c3, hp.kappa_patch3, ind(float(truth.mean()), 9))
    sparse = BorderPatchPrior(grid.shape, *triples, inner=(3, 3))
    bo = BackoffBorderPrior(grid.shape, *triples, kappa=hp.kappa_border, back=back, inner=(3, 3))
    s0 = sweep_seconds(PatchGibbs(OccupancyModel(grid, rays, GaussianRange(3.0), sparse), (3, 3), p_rand_patch=0.001))
    out = {"cells": grid.num_cells, "rays": rays.num_rays, "sparse_seconds": s0, "kappa": hp.kappa_border}
    print(f"\nbacked-off border prior, L = 9, {rows} x {cols}: sparse table {s0:.4f} s per map sample")
    model = OccupancyModel(grid, rays, GaussianRange(3.0), bo)
    for pe in (0.05, 0.2, 1.0):
        s = sweep_seconds(PatchGibbs(model, (3, 3), p_rand_patch=0.001, p_escape=pe))
        out[f"backoff_p_escape_{pe}_seconds"] = s
        out[f"backoff_p_escape_{pe}_ratio"] = s / s0
        print(f"  backed off, p_escape = {pe}: {s:.4f} s = {s / s0:.2f}x the sparse table (target <= 2x)")
    return out


def interleaved_sweep_seconds(kernels: dict, rounds: int = 7) -> dict[str, float]:
    """The best wall time of one sample (a sweep) of each kernel over ``rounds`` rounds that time every kernel
    in turn, so that a machine whose speed drifts during the run weighs on the baseline and on the priors
    compared with it alike. In each round a kernel first runs one untimed sample, so that the timed one finds
    its own data in the caches, as a chain's back-to-back sweeps do."""
    torch.manual_seed(0)
    state = {}
    for name, kernel in kernels.items():
        kernel.setup()
        state[name] = kernel.sample(kernel.current_params())
    best = dict.fromkeys(kernels, float("inf"))
    for _ in range(rounds):
        for name, kernel in kernels.items():
            state[name] = kernel.sample(state[name])
            t0 = time.perf_counter()
            state[name] = kernel.sample(state[name])
            best[name] = min(best[name], time.perf_counter() - t0)
    return best


def mrf_overhead() -> dict:
    """Single-cell and 3 x 3 patch sweeps on a 500 x 500 scene under the MRFs and the pattern fields, each
    against the independent prior's sweep timed in the same rounds (:func:`interleaved_sweep_seconds`)."""
    grid, scans = sparse_scene(
        500, 100, walls=max(4, 500 * 500 // 6000), seed=0, res=0.05, max_range_cells=75, sigma_cells=3.0, beams=720
    )
    rays = raycast(grid, scans)
    base = OccupancyModel(grid, rays, GaussianRange(3.0), IndependentPrior(0.234, grid.num_cells))
    models = {
        f"mrf{o}": OccupancyModel(grid, rays, GaussianRange(3.0), MRFPrior(grid.shape, o, 0.5, 0.234)) for o in (1, 2)
    }
    for kind in ("field", "field2"):  # the pattern fields (3 x 3 windows, one / two scales) of houseexpo
        models[kind] = OccupancyModel(grid, rays, GaussianRange(3.0), prior_by_name(f"{kind}:houseexpo", grid.shape))
    cell = interleaved_sweep_seconds({"independent": CellGibbs(base), **{k: CellGibbs(m) for k, m in models.items()}})
    s_ind = cell["independent"]
    out = {"cells": grid.num_cells, "rays": rays.num_rays, "independent_seconds": s_ind}
    print(f"\n500 x 500, {rays.num_rays:,} rays, L = 1 sweep: independent prior {s_ind:.4f} s")
    for name in models:
        s = cell[name]
        out[f"{name}_seconds"] = s
        out[f"{name}_ratio"] = s / s_ind
        label = f"MRF order {name[-1]}" if name.startswith("mrf") else f"pattern {name}"
        print(f"  {label}: {s:.4f} s = {s / s_ind:.2f}x the independent sweep (target <= 1.5x)")
    # 3 x 3 patch sweeps: every patch weighs all 2^9 configurations under the fields (window sums in
    # Gray-code order), against the independent prior's additive patch sweep
    fields = ("field", "field2")
    patch = interleaved_sweep_seconds(
        {"independent": PatchGibbs(base, patch=(3, 3)), **{k: PatchGibbs(models[k], patch=(3, 3)) for k in fields}},
        rounds=4,
    )
    s_ind9 = patch["independent"]
    out["independent_patch3_seconds"] = s_ind9
    print(f"  3 x 3 patch sweep: independent prior {s_ind9:.4f} s")
    for kind in fields:
        s = patch[kind]
        out[f"{kind}_patch3_seconds"] = s
        out[f"{kind}_patch3_ratio"] = s / s_ind9
        print(f"  pattern {kind}, 3 x 3 patches: {s:.4f} s = {s / s_ind9:.2f}x the independent patch sweep")
    return out


def main(quick: bool = False, overhead_only: bool = False) -> dict:
    if overhead_only:
        payload = {"mrf_500": mrf_overhead()}
        print("wrote", write_json("bench_priors_overhead", payload))
        return payload
    if quick:
        payload = {"table_5_1_quick_100x160": table_5_1(100, 160)}
        small = intel_size(500, poses=455, beams=180)
        scale = 1500**2 / small["cells"]
        small["extrapolated_1500x1500_seconds"] = small["seconds"] * scale
        print(f"  extrapolated to 1500 x 1500 (x{scale:.0f} cells): {small['seconds'] * scale:.2f} s per sample")
        payload["intel_size_quick_500"] = small
        payload["backoff_quick_100x160"] = backoff_vs_sparse(100, 160)
        print("wrote", write_json("bench_priors_quick", payload))
        return payload
    payload = {"table_5_1": table_5_1(), "intel_size": intel_size(), "mrf_500": mrf_overhead()}
    payload["backoff"] = backoff_vs_sparse()
    print("wrote", write_json("bench_priors", payload))
    return payload


if __name__ == "__main__":
    main(quick="--quick" in sys.argv[1:], overhead_only="--overhead" in sys.argv[1:])
