"""Table 6.6 (Merali 2020, Section 6.2.1): seconds per MCMC map sample on the Intel Lab experiments.

The thesis draws one map sample as one sweep of ``K / L`` patch updates (``L = 9``: 3 x 3 patches,
``K = 2.25 x 10^6`` cells: 30 m x 30 m at 2 cm) with the data-driven (``patch3:houseexpo``) and the
border-based data-driven (``border:houseexpo``) patch priors, and reports (Matlab, i7-6820HQ):

============  =================  ==========================
Experiment    data-driven [s]    border, data-driven [s]
============  =================  ==========================
1 (all poses)       6433                 1518
2 (1/2 poses)       3023                  723.6
3 (1/10 poses)       306.1                166.8
============  =================  ==========================

All experiments use half the beams (``beam_step=2``, Table 6.5). Here each configuration is
``PatchGibbs(model, patch=(3, 3))`` (systematic scan of the 3 x 3 tiling, aligned with the prior's tiles),
timed on the full map and, as the thesis suggests after Table 6.6, with sampling restricted to cells within
``--near`` cells (default 10, Fig. 6.16b) of a cell the experiment's own rays mapped (the observed cells
of its traditional-OGM evidence grid; ``region=`` of
:class:`~ogm_ppl.inference.mcmc.gibbs.PatchGibbs`: the rest of the map stays at its initial traditional-OGM
value, so the region chain samples the conditional of the visited patches given the rest).

Per configuration ``--sweeps`` sweeps run (default 3): the first (after ``setup``: initial OGM map and
every ray's first hit; it also pays numba's compilation the first time) is reported apart, the mean of the
others is the time per sample (wall clock; the CPU time of this single-threaded process is reported
beside it, as it moves less when other jobs share the cores). Also reported: model build seconds (raycast + model +
prior) and the
process's peak RSS (``resource.getrusage``), with the load average, since the machine may be shared.
The sensor is ``GaussianRange(--sigma-cells)`` (default 3.0 cells; the thesis's sigma is not restated
for Table 6.6). Both priors have ``outside_occupancy() = 0.5``, so their likelihood tables are equal and the
border model reuses the data-driven model's (built once per experiment; the second "build" is the prior
only). Models are freed between experiments to keep the peak RSS under 4 GB.

Default: ``--experiments 1,3`` (about 3-4 minutes on 2 idle cores at 2 cm; Experiment 1 is the headline
figure and 3 the sparsest); ``--experiments 1,2,3`` adds Experiment 2 (about a minute more).
``--resolution`` changes the cell size of the 30 m x 30 m grid (then ``K`` is not the thesis's and the
ratios are only indicative). Writes ``out/bench/bench_table_6_6.json``.
"""

from __future__ import annotations

import argparse
import copy
import ctypes
import gc
import os
import sys
import time
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, os.path.dirname(__file__))
from _common import peak_rss_mb, write_json

from ogm_ppl.datasets.carmen import read_carmen
from ogm_ppl.grid import Grid
from ogm_ppl.inference import PatchGibbs, evidence_grid
from ogm_ppl.metrics import near_mapped_mask
from ogm_ppl.models import delta_by_name
from ogm_ppl.models.occupancy import OccupancyModel
from ogm_ppl.priors.named import prior_by_name
from ogm_ppl.raycast import raycast
from ogm_ppl.sensors import GaussianRange

torch.set_default_dtype(torch.float64)

POSE_FRACTION = {1: 1.0, 2: 0.5, 3: 0.1}  # Table 6.5
THESIS_S = {1: {"dd": 6433.0, "border": 1518.0}, 2: {"dd": 3023.0, "border": 723.6}, 3: {"dd": 306.1, "border": 166.8}}
PRIORS = {"dd": "patch3:houseexpo", "border": "border:houseexpo"}
EXTENT_M, ORIGIN = 30.0, (-10.9, -23.65)


def intel_log_path() -> Path:
    """``shared/data/intel-lab/intel-corrected.log.gz`` beside the repository (CI), else under ``/work/shared``."""
    rel = Path("data") / "intel-lab" / "intel-corrected.log.gz"
    here = Path(__file__).resolve().parents[2] / "shared" / rel
    return here if here.is_file() else Path("/work/shared") / rel


def loadavg() -> str:
    try:
        return " ".join(Path("/proc/loadavg").read_text().split()[:3])
    except OSError:
        return "n/a"


def release_memory() -> None:
    """Collect garbage and hand freed heap pages back to the OS (glibc), so that one experiment's model
    does not add to the next one's peak RSS."""
    gc.collect()
    try:
        ctypes.CDLL("libc.so.6").malloc_trim(0)
    except (OSError, AttributeError):
        pass


def time_chain(model: OccupancyModel, region: np.ndarray | None, sweeps: int, init: dict | None) -> dict:
    """Set up ``PatchGibbs(model, (3, 3), region=region)`` and run ``sweeps`` sweeps (one map sample each)."""
    t = time.perf_counter()
    k = PatchGibbs(model, patch=(3, 3), region=region)
    if init is not None:
        k.initial_params = init
    k.setup(0)
    setup_s = time.perf_counter() - t
    p = k.initial_params
    times, cpu = [], []
    for _ in range(sweeps):
        t, c = time.perf_counter(), time.process_time()
        p = k.sample(p)
        times.append(time.perf_counter() - t)
        cpu.append(time.process_time() - c)
    rest = times[1:]
    return {
        "setup_s": setup_s,
        "first_sweep_s": times[0],
        "sweep_s": times[1:],
        "s_per_sample": float(np.mean(rest)) if rest else float("nan"),
        "cpu_s_per_sample": float(np.mean(cpu[1:])) if rest else float("nan"),
        "patches": len(k._anchors),
        "sampled_cells": len(k.sampled_cells()),
        "change_rate": k.diagnostics()["change rate"],
        "init": k.initial_params,
    }


def run_experiment(log, exp: int, grid: Grid, sigma_cells: float, near: float, sweeps: int) -> dict:
    t = time.perf_counter()
    scans = log.scans.subsample(pose_fraction=POSE_FRACTION[exp], beam_step=2)
    rays = raycast(grid, scans)
    raycast_s = time.perf_counter() - t
    # mapped: the evidence grid's observed cells (a non-zero traditional-OGM update). Not rays.reached(),
    # which caches two per-entry arrays (about 0.75 GB at Experiment 1) for the rest of the run.
    mapped = evidence_grid(rays, delta_by_name("haehnel")).observed.numpy().reshape(grid.shape)
    region = near_mapped_mask(mapped, near)
    out: dict = {
        "poses": int(scans.num_scans),
        "rays": int(rays.num_rays),
        "raycast_s": raycast_s,
        "mapped_cells": int(mapped.sum()),
        "region_cells": int(region.sum()),
        "priors": {},
    }
    init, model = None, None
    for key, name in PRIORS.items():
        t = time.perf_counter()
        prior = prior_by_name(name, grid.shape)
        if model is not None and model.prior.outside_occupancy() == prior.outside_occupancy():
            # the likelihood table (the build's cost) depends on the prior only through lambda_out
            # (rays cut by the grid edge): equal here, so the second model shares the first one's table
            model = copy.copy(model)
            model.prior = prior
            shared = True
        else:
            model = None
            release_memory()
            model = OccupancyModel(grid, rays, GaussianRange(sigma_cells), prior)
            shared = False
        build_s = time.perf_counter() - t
        res: dict = {"prior": name, "model_build_s": build_s, "shares_likelihood_table": shared}
        for label, reg in (("full", None), ("region", region)):
            r = time_chain(model, reg, sweeps, init)
            init = r.pop("init")  # the same starting map (thresholded traditional OGM) for every chain
            res[label] = r
            print(
                f"  exp {exp} {key:>6} {label:>6}: setup {r['setup_s']:6.1f} s, first sweep "
                f"{r['first_sweep_s']:6.2f} s, "
                f"{r['s_per_sample']:7.3f} s/sample (CPU {r['cpu_s_per_sample']:.3f} s; {r['patches']} patches, "
                f"{r['sampled_cells']} cells), "
                f"load {loadavg()}",
                flush=True,
            )
        res["peak_rss_mib"] = peak_rss_mb()
        out["priors"][key] = res
    del model, rays, scans
    release_memory()
    out["build_s"] = raycast_s + sum(v["model_build_s"] for v in out["priors"].values())
    return out


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--experiments", default="1,3", help="Intel experiments to run, e.g. 1,2,3 (default 1,3)")
    ap.add_argument("--resolution", type=float, default=0.02, help="cell size in metres (default 0.02)")
    ap.add_argument("--sweeps", type=int, default=3, help="sweeps per chain; the first is reported apart (default 3)")
    ap.add_argument("--sigma-cells", type=float, default=3.0, help="GaussianRange sigma in cells (default 3.0)")
    ap.add_argument("--near", type=float, default=10.0, help="region: cells within this many cells of a mapped cell")
    ap.add_argument("--log", type=Path, default=None, help="the Intel Lab CARMEN log (default: shared data)")
    a = ap.parse_args(argv)
    exps = [int(e) for e in a.experiments.split(",") if e.strip()]
    if not exps or any(e not in POSE_FRACTION for e in exps):
        ap.error(f"--experiments takes a subset of 1,2,3, got {a.experiments!r}")
    if a.sweeps < 2:
        ap.error("--sweeps must be >= 2 (the first sweep is reported apart)")
    n = round(EXTENT_M / a.resolution)
    grid = Grid((n, n), a.resolution, ORIGIN)
    load0 = loadavg()
    print(f"grid {n} x {n} = {grid.num_cells} cells at {a.resolution} m; sigma {a.sigma_cells} cells; load {load0}")
    t = time.perf_counter()
    log = read_carmen(a.log or intel_log_path(), max_usable_range=20.0)
    read_s = time.perf_counter() - t
    results = {}
    for e in exps:
        results[str(e)] = run_experiment(log, e, grid, a.sigma_cells, a.near, a.sweeps)
    print(
        f"\nTable 6.6, seconds per map sample (one sweep of 3 x 3 patches), K = {grid.num_cells}; thesis / ours in ()"
    )
    print(f"{'':>12} {'prior':>6} {'thesis':>8} {'full':>16} {'(CPU)':>8} {'region':>16} {'(CPU)':>8}")
    for name, r in results.items():
        for key in PRIORS:
            th = THESIS_S[int(name)][key]
            full, reg = r["priors"][key]["full"], r["priors"][key]["region"]
            fs, rs = full["s_per_sample"], reg["s_per_sample"]
            r["priors"][key].update(thesis_s=th, speedup_full=th / fs, speedup_region=th / rs)
            print(
                f"{'Experiment ' + name:>12} {key:>6} {th:8.1f} {fs:8.3f} ({th / fs:5.0f}x) "
                f"{full['cpu_s_per_sample']:8.3f} "
                f"{rs:8.3f} ({th / rs:5.0f}x) {reg['cpu_s_per_sample']:8.3f}"
            )
        print(
            f"{'':>12} build {r['build_s']:.1f} s (raycast {r['raycast_s']:.1f} s), region {r['region_cells']} of "
            f"{grid.num_cells} cells"
        )
    load1 = loadavg()
    print(f"peak RSS {peak_rss_mb():.0f} MiB; log read {read_s:.1f} s; load {load0} -> {load1}")
    payload = {
        "resolution_m": a.resolution,
        "cells": grid.num_cells,
        "sigma_cells": a.sigma_cells,
        "near_cells": a.near,
        "sweeps": a.sweeps,
        "log_read_s": read_s,
        "experiments": results,
        "peak_rss_mib": peak_rss_mb(),
        "loadavg_start": load0,
        "loadavg_end": load1,
    }
    print("wrote", write_json("bench_table_6_6", payload))
    return payload


if __name__ == "__main__":
    main()
