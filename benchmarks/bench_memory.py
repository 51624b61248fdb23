"""Peak memory of a model and its sampler, against the estimate of the memory guard.

``ogm_ppl.models.occupancy.check_memory`` refuses a model whose rays need more than the free memory, by
:func:`~ogm_ppl.models.occupancy.memory_needed`: :data:`~ogm_ppl.models.occupancy.BYTES_PER_CROSSING` per
ray-cell crossing (the ray structure, the likelihood table, the ray index in cell order, a Gibbs kernel's
state) and the likelihood table's working blocks. This measures the peak on real and simulated problems of
several sizes: each case runs in a process of its own, compiles the kernels on a tiny problem, reads its
scans, then traces the rays, builds the model and a kernel and runs one sweep; the rise of the process's
peak resident memory over its peak before the ray cast is the case's need. Kernels: single-cell Gibbs under
the independent prior, and patch Gibbs (L = 9) under the backed-off 3 x 3 table. (The simulated case's
peak before the ray cast includes the simulation's own, so its rise under-counts.)

Prints each case's measured rise, the guard's estimate and their ratio (above 1: the guard under-counts and a
problem that does not fit could start; far below 1: it refuses work that would fit); writes
out/bench/bench_memory.json.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

sys.path.insert(0, os.path.dirname(__file__))
from _common import peak_rss_mb, write_json

ROOT = Path(__file__).resolve().parent.parent
DATA = ROOT.parent / "shared" / "data"
INTEL = DATA / "intel-lab" / "intel-corrected.log.gz"
FHW = DATA / "carmen" / "fhw-corrected.log.gz"

#: name -> (source, resolution m, pose fraction, beam step, kernel)
CASES: dict[str, tuple[str, float, float, int, str]] = {
    "intel 10 cm, all poses, cell": ("intel", 0.10, 1.0, 2, "cell"),
    "intel 5 cm, 10 % poses, cell": ("intel", 0.05, 0.1, 2, "cell"),
    "intel 5 cm, 10 % poses, patch": ("intel", 0.05, 0.1, 2, "patch"),
    "intel 5 cm, 50 % poses, cell": ("intel", 0.05, 0.5, 2, "cell"),
    "fhw 5 cm, 25 % poses, cell": ("fhw", 0.05, 0.25, 1, "cell"),
    "intel 5 cm, all poses, cell": ("intel", 0.05, 1.0, 1, "cell"),
    "simulated 800 x 800, 200 poses, cell": ("sim", 0.05, 1.0, 1, "cell"),
}


def _scans(source: str, res: float, fraction: float, step: int):
    from ogm_ppl import Grid
    from ogm_ppl.datasets import read_carmen

    if source == "sim":
        from _common import sparse_scene

        grid, scans = sparse_scene(800, 200, 60, max_range_cells=150, beams=360)
        return grid, scans
    log = read_carmen(INTEL if source == "intel" else FHW, max_usable_range=20.0)
    scans = log.scans.subsample(pose_step=1, beam_step=step, pose_fraction=None if fraction == 1 else fraction)
    xmin, xmax, ymin, ymax = scans.extent()
    cols, rows = int((xmax - xmin + 2) / res) + 1, int((ymax - ymin + 2) / res) + 1
    return Grid((rows, cols), res, (xmin - 1.0, ymin - 1.0)), scans


def run_case(name: str) -> dict:
    """One case in this process: ``{crossings, rise_mib, bytes_per_crossing, seconds}``."""
    from ogm_ppl import GaussianRange, OccupancyModel, raycast
    from ogm_ppl.inference.mcmc import CellGibbs, PatchGibbs, run_gibbs
    from ogm_ppl.priors import IndependentPrior, prior_by_name

    source, res, fraction, step, kernel = CASES[name]

    def build(grid, scans):
        rays = raycast(grid, scans)
        prior = (
            IndependentPrior(0.5, grid.num_cells)
            if kernel == "cell"
            else prior_by_name("patch3_bo:houseexpo", grid.shape)
        )
        model = OccupancyModel(grid, rays, GaussianRange(1.0), prior)
        k = CellGibbs(model) if kernel == "cell" else PatchGibbs(model, (3, 3))
        run_gibbs(k, 1, warmup=0, seed=0, progress=False)
        return rays

    from _common import sparse_scene

    build(*sparse_scene(60, 3, 2, beams=36))  # compiles or loads the kernels: their memory is not per crossing
    grid, scans = _scans(source, res, fraction, step)
    before = peak_rss_mb()
    t0 = time.perf_counter()
    rays = build(grid, scans)
    rise = peak_rss_mb() - before
    crossings = int(rays.cells.size)
    from ogm_ppl.models.occupancy import memory_needed

    return {
        "guard_estimate_mib": round(memory_needed(rays) / 2**20, 1),
        "cells": int(grid.num_cells),
        "rays": int(rays.num_rays),
        "table_entries": int(rays.num_rays * (int(rays.lengths.max()) + 1)),
        "crossings": crossings,
        "rise_mib": round(rise, 1),
        "bytes_per_crossing": round(rise * 2**20 / crossings, 1),
        "seconds": round(time.perf_counter() - t0, 2),
    }


def main() -> None:
    if len(sys.argv) == 3 and sys.argv[1] == "--case":
        print(json.dumps(run_case(sys.argv[2])))
        return
    from ogm_ppl.models.occupancy import BYTES_PER_CROSSING

    rows = {}
    for name in CASES:
        out = subprocess.run(
            [sys.executable, __file__, "--case", name], capture_output=True, text=True, check=True, timeout=240
        )
        r = json.loads(out.stdout.strip().splitlines()[-1])
        r["measured_over_estimate"] = round(r["rise_mib"] / r["guard_estimate_mib"], 2)
        rows[name] = r
        print(
            f"{name:40s} {r['crossings'] / 1e6:6.1f} M crossings  measured +{r['rise_mib']:7.1f} MiB  "
            f"guard {r['guard_estimate_mib']:7.1f} MiB  x{r['measured_over_estimate']:.2f}  "
            f"({r['bytes_per_crossing']:.1f} B/crossing in all)",
            flush=True,
        )
    write_json("bench_memory", {"bytes_per_crossing_constant": BYTES_PER_CROSSING, "cases": rows})


if __name__ == "__main__":
    main()
