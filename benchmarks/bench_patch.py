"""Patch maps on a 500 x 500 map (Section 3.2 asks for minutes, not hours, for 3 x 3 overlapping patches).

The 100-pose x 720-beam scene of the other benchmarks; MAP reference by ICM. Times: online patch map
(forward model, 3 x 3 tiles), offline (3 x 3 tiles), offline with a 3 x 3 patch centred on every cell, and
traditional OGM as the baseline in the same run. Writes out/bench/bench_patch.json.
"""

from __future__ import annotations

import os
import sys
import time

import torch

sys.path.insert(0, os.path.dirname(__file__))
from _common import peak_rss_mb, sparse_scene, write_json

from ogm_ppl import GaussianRange, OccupancyModel, raycast
from ogm_ppl.inference import evidence_grid
from ogm_ppl.inference.exact import map_estimate
from ogm_ppl.inference.patch_map import offline_patch_map, online_patch_map, reference_map
from ogm_ppl.models import delta_by_name
from ogm_ppl.priors import IndependentPrior

torch.set_default_dtype(torch.float64)


def timed(fn):
    t = time.perf_counter()
    out = fn()
    return out, time.perf_counter() - t


def main() -> dict:
    grid, scans = sparse_scene(500, 100, walls=40)
    rays = raycast(grid, scans)
    model = OccupancyModel(grid, rays, GaussianRange(3.0), IndependentPrior(0.5, grid.num_cells))
    res = {}
    _, res["traditional OGM (Haehnel)"] = timed(lambda: evidence_grid(rays, delta_by_name("haehnel")))
    _, res["MAP (ICM)"] = timed(lambda: map_estimate(model))
    ref = reference_map(model)
    _, res["online patch map 3x3"] = timed(lambda: online_patch_map(model, (3, 3)))
    _, res["offline patch map 3x3"] = timed(lambda: offline_patch_map(model, (3, 3), reference=ref))
    _, res["offline patch map 3x3, overlapping"] = timed(
        lambda: offline_patch_map(model, (3, 3), reference=ref, overlap=True)
    )
    for k, v in res.items():
        print(f"{k:<40} {v:9.2f} s")
    print(f"peak RSS {peak_rss_mb():.0f} MiB")
    payload = {"cells": grid.num_cells, "rays": rays.num_rays, "seconds": res, "peak_rss_mib": peak_rss_mb()}
    print("wrote", write_json("bench_patch", payload))
    return payload


if __name__ == "__main__":
    main()
