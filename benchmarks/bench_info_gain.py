"""Information gain of candidate poses from posterior samples on the 500 x 500 reference scene.

The scene of the other benchmarks (``sparse_scene(500, 100, walls=40)``: 5 cm cells, 75-cell max range,
``GaussianRange(3.0)``). Samples: 64 maps drawn cell-independently from the traditional-OGM marginals of
the scene's scans (cheap, and with the spread of first hits of a real posterior: sharp along mapped walls,
random in unknown space). Candidates: 100 poses in cells the OGM calls free (``p < 0.3``), 360 beams each.

Times (best of a few): ray casting the candidates once, the exact per-beam MI
(:func:`~ogm_ppl.exploration.beam_information`, the target: under 1 s for 100 x 360 x 64), the independent-cell
baseline, the nested Monte-Carlo scan MI, and a plain vectorised torch implementation of the per-beam MI
measured in the same run (on a subset of the candidates, scaled to 100) whose values must agree.
Writes out/bench/bench_info_gain.json.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time

import numpy as np
import torch

sys.path.insert(0, os.path.dirname(__file__))
from _common import best_time, peak_rss_mb, sparse_scene, write_json

from ogm_ppl import GaussianRange, raycast
from ogm_ppl.exploration import (
    beam_information,
    candidate_rays,
    independent_information,
    scan_information,
)
from ogm_ppl.inference import evidence_grid
from ogm_ppl.models import delta_by_name

torch.set_default_dtype(torch.float64)
SIGMA = 3.0


def torch_beam_information(grid, sigma, samples, cr, chunk=1500):
    """Plain torch: dense first hits of every sample, Gaussian bin probabilities by ``ndtr``, MI in bits."""
    S = samples.shape[0]
    K = grid.num_cells
    lengths = torch.from_numpy(cr.lengths)
    R, Wm = len(lengths), int(lengths.max())
    entry_ray = torch.repeat_interleave(torch.arange(R), lengths)
    kappa = torch.arange(len(cr.cells)) - torch.repeat_interleave(torch.from_numpy(cr.offsets[:-1]), lengths)
    dense = torch.full((R, Wm), K, dtype=torch.int64)
    dense[entry_ray, kappa] = torch.from_numpy(cr.cells)
    T = torch.zeros(R, Wm, dtype=torch.float64)
    T[entry_ray, kappa] = torch.from_numpy(cr.t_enter).double()
    occ_all = torch.cat([samples.bool(), torch.zeros(S, 1, dtype=torch.bool)], 1)
    F = cr.max_range_cells
    J = math.ceil((F + 1) - 1e-12)
    e = torch.tensor([-0.5 + j for j in range(J + 1)], dtype=torch.float64)
    e[J] = F + 0.5
    out = torch.empty(R, dtype=torch.float64)
    B = cr.num_beams
    for a in range(0, R, chunk):
        b = min(R, a + chunk)
        occ = occ_all[:, dense[a:b]]  # S x r x Wm
        free_pose = ~occ[:, :, 0]  # condition on the candidate's cell
        occ[:, :, 0] = False
        n = lengths[a:b]
        first = torch.where(occ.any(-1), occ.to(torch.uint8).argmax(-1), n[None, :])  # S x r
        w = free_pose.double() / free_pose.double().sum(0, keepdim=True)
        pf = torch.zeros(b - a, Wm + 1, dtype=torch.float64)
        pf.scatter_add_(1, first.T, w.T)
        f = T[a:b] + 0.5  # r x Wm
        cdf = torch.special.ndtr((e[None, None, :] - f[:, :, None]) / sigma)
        cdf[:, :, 0] = 0.0
        hit = cdf[:, :, 1:] - cdf[:, :, :-1]
        mx = 1 - torch.special.ndtr((F + 0.5 - f) / sigma)
        rows = torch.cat([hit, mx[:, :, None]], -1)  # r x Wm x (J + 1)
        none = torch.zeros(b - a, 1, J + 1, dtype=torch.float64)
        none[:, :, J] = 1.0
        rows = torch.cat([rows, none], 1)
        col = torch.arange(Wm + 1)[None, :]
        rows = torch.where((col == n[:, None])[:, :, None], none.expand_as(rows), rows)
        q = torch.einsum("rk,rkj->rj", pf, rows)
        ok = rows > 0
        lr = torch.where(ok, torch.log(torch.where(ok, rows, 1.0) / q[:, None, :].clamp(min=1e-300)), 0.0)
        out[a:b] = torch.einsum("rk,rkj->r", pf, rows * lr) / math.log(2.0)
    del B
    return out.reshape(-1, cr.num_beams)


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--candidates", type=int, default=100)
    ap.add_argument("--beams", type=int, default=360)
    ap.add_argument("--samples", type=int, default=64)
    ap.add_argument("--draws", type=int, default=64, help="nested Monte-Carlo draws per candidate (scan MI)")
    ap.add_argument("--baseline-candidates", type=int, default=4, help="candidates the torch baseline runs on")
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args(argv)

    grid, scans = sparse_scene(500, 100, walls=40)
    rays = raycast(grid, scans)
    ogm = evidence_grid(rays, delta_by_name("haehnel")).probabilities.detach().double()
    g = torch.Generator().manual_seed(0)
    samples = (torch.rand(args.samples, grid.num_cells, generator=g, dtype=torch.float64) < ogm).to(torch.uint8)
    rng = np.random.default_rng(1)
    free = np.flatnonzero(ogm.numpy() < 0.3)
    pick = free[rng.choice(len(free), args.candidates, replace=False)]
    r, c = np.divmod(pick, grid.cols)
    res = grid.resolution
    poses = np.c_[(c + 0.5) * res, (r + 0.5) * res, rng.uniform(-np.pi, np.pi, args.candidates)]
    angles = np.arange(args.beams) * (2 * np.pi / args.beams)
    sensor = GaussianRange(SIGMA)
    max_range = scans.max_range

    t0 = time.perf_counter()
    cr = candidate_rays(grid, poses, angles, max_range)
    cold = beam_information(grid, sensor, samples, cr)  # compiles (or loads the numba cache)
    first_call = time.perf_counter() - t0
    t = {}
    t["candidate_rays"] = best_time(lambda: candidate_rays(grid, poses, angles, max_range), args.repeat)
    t["beam_information"] = best_time(lambda: beam_information(grid, sensor, samples, cr), args.repeat)
    t["candidate_rays + beam_information"] = t["candidate_rays"] + t["beam_information"]
    marg = samples.double().mean(0)
    t["independent_information"] = best_time(lambda: independent_information(grid, sensor, ogm, cr), args.repeat)
    scan_information(grid, sensor, samples, candidate_rays(grid, poses[:2], angles, max_range), num_draws=4)
    t0 = time.perf_counter()
    scan = scan_information(grid, sensor, samples, cr, num_draws=args.draws, generator=torch.Generator().manual_seed(0))
    t["scan_information"] = time.perf_counter() - t0

    nb_ = args.baseline_candidates
    sub = candidate_rays(grid, poses[:nb_], angles, max_range)
    t0 = time.perf_counter()
    ref = torch_beam_information(grid, SIGMA, samples, sub)
    t_torch = (time.perf_counter() - t0) * args.candidates / nb_
    err = float((ref - cold[:nb_]).abs().max())
    assert err < 1e-9, f"the torch baseline disagrees with beam_information by {err}"
    t["plain torch beam MI (scaled to all candidates)"] = t_torch

    ind = independent_information(grid, sensor, marg, cr)
    print(f"{args.candidates} candidates x {args.beams} beams x {args.samples} samples on {grid.shape}")
    for k, v in t.items():
        print(f"{k:<50} {v:9.3f} s")
    speedup = t_torch / t["beam_information"]
    print(f"beam_information vs plain torch: {speedup:.1f}x (max |difference| {err:.1e} bits)")
    print(f"first call (compile or cache load): {first_call:.1f} s; peak RSS {peak_rss_mb():.0f} MiB")
    bits = cold.sum(1)
    print(
        f"per-candidate sum of beam MI: mean {bits.mean():.2f} bits; scan MI mean {scan.mean.mean():.2f} bits "
        f"(stderr mean {scan.stderr.mean():.3f}); independent on sample marginals {ind.sum(1).mean():.2f} bits"
    )
    payload = {
        "scene": {"cells": grid.num_cells, "resolution": res, "max_range_cells": max_range / res, "sigma_cells": SIGMA},
        "candidates": args.candidates,
        "beams": args.beams,
        "samples": args.samples,
        "scan_draws": args.draws,
        "seconds": t,
        "target_seconds": 1.0,
        "speedup_vs_torch": speedup,
        "max_abs_difference_bits": err,
        "first_call_seconds": first_call,
        "mean_beam_mi_sum_bits": float(bits.mean()),
        "mean_scan_mi_bits": float(scan.mean.mean()),
        "mean_scan_stderr_bits": float(scan.stderr.mean()),
        "threads": torch.get_num_threads(),
        "peak_rss_mib": peak_rss_mb(),
    }
    print("wrote", write_json("bench_info_gain", payload))
    return payload


if __name__ == "__main__":
    main()
