"""Exact posteriors: brute force over 2^K maps and the pose-constrained 1D solution.

The thesis quotes "several hours" for brute force at K = 20 (Section 2.3); the target here is under 10 s
for K = 20 with 6 readings. Baseline in the same run: a plain per-map Python loop (timed on the first
4096 maps and scaled by the map count). Pose-constrained: K = 10^2..10^4 with N = 6 and N = 600
readings; its cost grows as K * N, brute force as 2^K. Writes out/bench/bench_exact.json.
"""

from __future__ import annotations

import math
import os
import sys
import time

import numpy as np
import torch

sys.path.insert(0, os.path.dirname(__file__))
from _common import peak_rss_mb, write_json

from ogm_ppl import GaussianRange, OccupancyModel, raycast
from ogm_ppl.datasets import THESIS_TOY_READINGS, toy_1d
from ogm_ppl.inference.exact import brute_force, pose_constrained_1d
from ogm_ppl.priors import IndependentPrior

torch.set_default_dtype(torch.float64)


def model(K: int, readings) -> OccupancyModel:
    toy = toy_1d(num_cells=K + 1, wall=1, readings=readings)
    return OccupancyModel(toy.grid, raycast(toy.grid, toy.scans), GaussianRange(3.0), IndependentPrior(0.5, K + 1))


def python_loop_seconds_per_map(m: OccupancyModel, n_maps: int = 4096) -> float:
    """Plain Python: for each map, walk each ray to its first occupied cell and add log-likelihoods."""
    sensor, rays = m.sensor, m.rays
    z = rays.z.tolist()
    lat = m.latent.tolist()
    t = time.perf_counter()
    acc = []
    for code in range(n_maps):
        occ = {c for i, c in enumerate(lat) if code >> i & 1}
        lp = len(occ) * math.log(0.5) + (len(lat) - len(occ)) * math.log(0.5)
        for r in range(rays.num_rays):
            cells = rays.ray(r).tolist()
            f = next((k for k, c in enumerate(cells) if c in occ), len(cells))
            lp += float(sensor.log_prob(torch.tensor(float(z[r])), f, len(cells) - 1))
        acc.append(lp)
    return (time.perf_counter() - t) / n_maps


def main() -> dict:
    rows = []
    print(f"{'K':>4}{'maps':>12}{'brute force (s)':>17}{'python loop (s, est.)':>24}{'speed-up':>10}")
    per_map = python_loop_seconds_per_map(model(16, THESIS_TOY_READINGS))
    for K in (16, 18, 20):
        m = model(K, THESIS_TOY_READINGS)
        t = time.perf_counter()
        post = brute_force(m)
        _ = post.marginals
        dt = time.perf_counter() - t
        est = per_map * 2**K
        rows.append({"K": K, "maps": 2**K, "seconds": dt, "python_loop_seconds_estimated": est})
        print(f"{K:>4}{2**K:>12,}{dt:>17.3f}{est:>24.1f}{est / dt:>9.0f}x")
    k20 = rows[-1]["seconds"]
    print(f"K = 20 with 6 readings: {k20:.2f} s (target < 10 s: {'met' if k20 < 10 else 'NOT met'})")
    ratio = [rows[i + 1]["seconds"] / rows[i]["seconds"] for i in range(2)]
    print(f"brute-force time ratio per +2 cells: {ratio[0]:.2f}, {ratio[1]:.2f} (2^K scaling predicts 4)")

    pc_rows = []
    print(f"\n{'K':>7}{'N':>6}{'model (s)':>11}{'pose-constrained (s)':>22}")
    rng = np.random.default_rng(0)
    for N in (6, 600):
        for K in (100, 1000, 10000):
            readings = np.clip(np.rint(rng.normal(K * 0.6, 3.0, N)), 0, K) if N > 6 else THESIS_TOY_READINGS
            t = time.perf_counter()
            m = model(K, readings)
            t_model = time.perf_counter() - t
            t = time.perf_counter()
            post = pose_constrained_1d(m)
            _ = post.marginals
            dt = time.perf_counter() - t
            pc_rows.append({"K": K, "N": N, "model_seconds": t_model, "seconds": dt})
            print(f"{K:>7}{N:>6}{t_model:>11.4f}{dt:>22.5f}")
    payload = {
        "brute_force": rows,
        "python_loop_seconds_per_map": per_map,
        "pose_constrained": pc_rows,
        "peak_rss_mib": peak_rss_mb(),
    }
    print(f"peak RSS {peak_rss_mb():.0f} MiB")
    print("wrote", write_json("bench_exact", payload))
    return payload


if __name__ == "__main__":
    main()
