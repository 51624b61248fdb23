"""Traditional OGM speed: traversal plus evidence-grid update (issue: foundation).

Scene: a 500 x 500 grid at 5 cm, 100 scan poses x 720 beams (72,000 rays), max range 75 cells, range
noise sigma = 3 cells, sparse obstacles so that most beams are max-range readings. Every method does the
same work (Hähnel's update term, traversal included) and must give the same evidence grid.

Compared in the same run, on one core (and ours also on ``--threads`` threads, default every core):
  ours (fused)   ogm_ppl.inference.evidence_grid_from_scans(threads=1): one compiled pass, no ray structure kept
  ours (fused, N threads)  the same on N threads (the rays split into parts, fixed-point sums: the same map
                 to the last bit, checked)
  ours (CSR)     raycast() then evidence_grid(): builds the ray -> cells structure other algorithms use
  numpy          ogm_ppl.reference.evidence_grid_numpy, batched and vectorised
  python loop    ogm_ppl.reference.evidence_grid_reference, one ray at a time (timed on a subset)
  octomap        OctoMap's insertPointCloud through octomap-python (optional; z = 0 point clouds)

Rates: rays/s and ray-cell updates/s, where ray-cell updates = cells traversed within max range and
grid (the same count for every method). Targets: the threaded fused pass at least 15x OctoMap and 8x numpy.

    python benchmarks/bench_ogm.py [--threads N]   (writes out/bench/bench_ogm.json)
"""

from __future__ import annotations

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")  # one core for OctoMap too
os.environ.setdefault("NUMBA_NUM_THREADS", str(os.cpu_count() or 1))  # ours: one thread, then --threads

import argparse
import math
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(__file__))
from _common import best_time, peak_rss_mb, sparse_scene, write_json

from ogm_ppl import Scans, raycast
from ogm_ppl.inference import evidence_grid, evidence_grid_from_scans
from ogm_ppl.models import Moravec
from ogm_ppl.reference import evidence_grid_numpy, evidence_grid_reference

RES, N, F, SIGMA = 0.05, 500, 75, 3.0
L4 = math.log(4.0)


def scene(seed: int = 0):
    return sparse_scene(N, 100, walls=40, seed=seed, res=RES, max_range_cells=F, sigma_cells=SIGMA)


def octomap_time(scans: Scans):
    try:
        import octomap
    except ImportError:
        return None, "octomap-python not installed (pip install -e '.[bench]')"
    theta = scans.world_angles()
    rng = np.where(scans.is_max, scans.max_range * 1.001, scans.ranges)  # max-range: free space only
    clouds = []
    for s in range(scans.num_scans):
        x, y = scans.poses[s, :2]
        pts = np.c_[x + rng[s] * np.cos(theta[s]), y + rng[s] * np.sin(theta[s]), np.zeros(len(rng[s]))]
        clouds.append((np.ascontiguousarray(pts), np.array([x, y, 0.0])))

    def run():
        tree = octomap.OcTree(RES)
        tree.setProbHit(0.8)
        tree.setProbMiss(0.2)
        for pts, origin in clouds:
            tree.insertPointCloud(pts, origin, maxrange=scans.max_range)
        return tree

    return best_time(run, repeat=3), "ok"


def main() -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--threads", type=int, default=int(os.environ["NUMBA_NUM_THREADS"]), help="threads of ours")
    args = ap.parse_args()
    T = args.threads
    t0 = time.perf_counter()
    grid, scans = scene()
    rays = raycast(grid, scans)
    nnz, R = rays.nnz, rays.num_rays
    haehnel = Moravec.haehnel()
    print(
        f"scene: {N}x{N} cells at {RES} m, {R} rays, {scans.is_max.mean():.1%} max-range, "
        f"{nnz / 1e6:.2f} M ray-cell updates ({nnz / R:.1f} per ray); setup {time.perf_counter() - t0:.1f} s"
    )

    t = time.perf_counter()
    evidence_grid_from_scans(grid, scans, haehnel, threads=1)
    compile_s = time.perf_counter() - t
    ours_fused = evidence_grid_from_scans(grid, scans, haehnel, threads=1).log_odds.numpy()
    same_threads = bool(
        np.array_equal(evidence_grid_from_scans(grid, scans, haehnel, threads=T).log_odds.numpy(), ours_fused)
    )
    t_fused = best_time(lambda: evidence_grid_from_scans(grid, scans, haehnel, threads=1), repeat=7)
    t_threads = best_time(lambda: evidence_grid_from_scans(grid, scans, haehnel, threads=T), repeat=7)
    t_csr = best_time(lambda: evidence_grid(raycast(grid, scans), haehnel), repeat=5)
    t_numpy = best_time(lambda: evidence_grid_numpy(grid, scans, L4, -L4), repeat=2, warmup=0)
    ref_np = evidence_grid_numpy(grid, scans, L4, -L4)
    sub = Scans(scans.poses[:10], scans.angles[:10], scans.ranges[:10], scans.max_range)
    sub_nnz = raycast(grid, sub).nnz
    t = time.perf_counter()
    ref_loop = evidence_grid_reference(grid, sub, L4, -L4)
    t_loop_sub = time.perf_counter() - t
    t_loop = t_loop_sub * nnz / sub_nnz  # extrapolated by work
    agree_numpy = float(np.abs(ours_fused - ref_np).max())
    agree_loop = float(np.abs(evidence_grid_from_scans(grid, sub, haehnel).log_odds.numpy() - ref_loop).max())
    t_octo, octo_status = octomap_time(scans)

    rows = {
        "ours (fused)": t_fused,
        f"ours (fused, {T} threads)": t_threads,
        "ours (CSR)": t_csr,
        "numpy (batched)": t_numpy,
        "python loop": t_loop,
    }
    if t_octo is not None:
        rows["octomap"] = t_octo
    print(f"\n{'method':<18}{'time (s)':>10}{'rays/s':>14}{'M updates/s':>14}{'ours fused is':>16}")
    for name, sec in rows.items():
        print(f"{name:<18}{sec:>10.4f}{R / sec:>14,.0f}{nnz / sec / 1e6:>14.1f}{sec / t_fused:>15.1f}x")
    if t_octo is None:
        print(f"octomap: {octo_status}")
    print(f"\npython loop timed on 10 scans ({sub_nnz} updates, {t_loop_sub:.2f} s) and scaled by work")
    print(f"max |ours - numpy| = {agree_numpy:.2e}, max |ours - python loop| = {agree_loop:.2e}")
    print(f"numba compile/load on first call: {compile_s:.2f} s; peak RSS {peak_rss_mb():.0f} MiB")
    target = nnz / t_fused / 1e6
    print(f"target >= 100 M updates/s: {target:.0f} M/s -> {'met' if target >= 100 else 'NOT met'}")
    vs = {k: rows[k] / t_threads for k in rows}
    octo = f"{vs['octomap']:.1f}x OctoMap (target 15), " if "octomap" in vs else ""
    print(
        f"{T} threads: {t_fused / t_threads:.2f}x one thread, {octo}{vs['numpy (batched)']:.1f}x numpy (target 8); "
        f"the same map as one thread to the last bit: {same_threads}; load {os.getloadavg()[0]:.2f}"
    )
    payload = {
        "scene": {
            "grid": [N, N],
            "resolution_m": RES,
            "rays": R,
            "max_range_cells": F,
            "sigma_cells": SIGMA,
            "max_range_fraction": float(scans.is_max.mean()),
            "ray_cell_updates": nnz,
        },
        "seconds": rows,
        "rays_per_second": {k: R / v for k, v in rows.items()},
        "updates_per_second": {k: nnz / v for k, v in rows.items()},
        "speedup_of_fused_over": {k: v / t_fused for k, v in rows.items()},
        "threads": T,
        "speedup_of_threaded_over": vs,
        "threaded_equals_one_thread": same_threads,
        "load_1min": os.getloadavg()[0],
        "octomap_status": octo_status,
        "python_loop_subset": {"ray_cell_updates": sub_nnz, "seconds": t_loop_sub},
        "max_abs_difference": {"numpy": agree_numpy, "python_loop": agree_loop},
        "first_call_seconds": compile_s,
        "peak_rss_mib": peak_rss_mb(),
    }
    print("wrote", write_json("bench_ogm", payload))
    return payload


if __name__ == "__main__":
    main()
