"""Chromatic tile sweeps in threads (:class:`~ogm_ppl.inference.mcmc.parallel.ChromaticCellGibbs`) on Intel at 2 cm.

The model is Table 6.6's (``bench_table_6_6.py``): the Intel Lab log, 30 m x 30 m at 2 cm (1500 x 1500 =
2.25 M cells), half the beams, ``--experiment`` 3 (a tenth of the poses; 1: all), ``GaussianRange(3 cells)``,
and here an independent prior (``lambda = 0.3``) or ``--prior mrf`` (4-connected, ``psi = 0.5``). Each
``--configs`` entry ``range:tiles`` builds the model with readings cut at ``range`` metres
(``max_usable_range``; Table 6.6 uses 20 m) and, after a warm-up sweep (numba's compilation):

* the serial single-cell sweep (``CellGibbs``, systematic heat bath), the baseline;
* for each tile side ``T`` (``auto``: the longest ray's extent, so that no cell is long): the chromatic
  sweep with 1 and with 2 threads (``numba.set_num_threads``), the layout (tiles per colour, the fraction
  of long cells: cells on a ray that reaches two tiles of one colour, swept serially after the four colour
  phases), and each tile's cost (one ``tile_pass`` at a time, single thread) and the long phase's, from
  which a scaling model predicts a sweep on ``P`` cores: per colour the makespan of the tiles taken largest
  first by whichever of ``P`` threads is free (as the kernel takes them), summed, plus the long phase;
* peak RSS (``ru_maxrss``, a process-wide peak) after the serial sweeps and after the threaded ones (the
  serial kernel freed first); comparable for the first configuration only.

``--patch-range`` (metres; ``0``: skip) adds 3 x 3 patch sweeps on the model of that range under Table 6.6's
priors (``--patch-priors``: the patch table and the border prior learned on HouseExpo): the serial
``PatchGibbs`` and the chromatic ``ChromaticPatchGibbs`` (the longest ray's extent rounded up to a multiple of
3) with 1 and 2 threads, from the same start and seed, the two thread counts checked to give the same map.

At 20 m the rays reach 1000 cells, two thirds of the grid's side, so tiles as large as the longest ray
leave one tile per colour and smaller tiles leave most cells long; at 5 m (250 cells) every cell is short
with 9 tiles per colour. The machine may be shared (the load average is printed): timings are then noisy,
the per-tile costs less so. Writes ``out/bench/bench_parallel.json``; about 4 minutes.
"""

from __future__ import annotations

import argparse
import copy
import gc
import os
import sys
import time

os.environ.setdefault("NUMBA_NUM_THREADS", "2")

import numba
import numpy as np
import torch

sys.path.insert(0, os.path.dirname(__file__))
from _common import peak_rss_mb, write_json
from bench_table_6_6 import EXTENT_M, ORIGIN, POSE_FRACTION, intel_log_path, loadavg, release_memory

from ogm_ppl.datasets.carmen import read_carmen
from ogm_ppl.grid import Grid
from ogm_ppl.inference._kernels import parallel as par
from ogm_ppl.inference.mcmc import CellGibbs, PatchGibbs
from ogm_ppl.inference.mcmc.gibbs import _SCAN_CODES
from ogm_ppl.inference.mcmc.parallel import ChromaticCellGibbs, ChromaticPatchGibbs
from ogm_ppl.models.occupancy import OccupancyModel
from ogm_ppl.priors import IndependentPrior, MRFPrior, prior_by_name
from ogm_ppl.raycast import raycast
from ogm_ppl.sensors import GaussianRange

torch.set_default_dtype(torch.float64)


def rss_mb() -> float:
    """The current resident set size (MiB)."""
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    return float("nan")


def timed_sweeps(kernel, sweeps: int) -> tuple[float, list[float]]:
    """``sweeps`` sweeps after :meth:`setup` (the first reported apart: it may compile); returns the mean
    of the others and all the times."""
    p = kernel.current_params()
    times = []
    for _ in range(sweeps):
        t = time.perf_counter()
        p = kernel.sample(p)
        times.append(time.perf_counter() - t)
    return float(np.mean(times[1:])), times


def lpt_makespan(costs: np.ndarray, P: int) -> float:
    """The makespan of ``costs`` taken largest first by whichever of ``P`` threads is free (``par.take_tile``)."""
    load = np.zeros(P)
    for c in np.sort(costs)[::-1]:
        load[np.argmin(load)] += c
    return float(load.max()) if len(costs) else 0.0


def tile_costs(kernel: ChromaticCellGibbs) -> tuple[list[np.ndarray], float]:
    """Seconds of each tile's pass (single thread, one at a time; per colour) and of the long phase: one
    sweep in the kernel's order."""
    lay = kernel.layout
    st, inf32, prior = kernel._st, kernel._inf32, kernel._compiled
    seed = np.uint64(12345)
    scan = _SCAN_CODES[kernel.scan]
    per_colour = []
    for colour in range(par.COLOURS):
        costs = []
        for t in lay.col_tiles[lay.col_off[colour] : lay.col_off[colour + 1]]:
            t0 = time.perf_counter()
            par.tile_pass(st, inf32, prior, lay, int(t), seed, scan, kernel._rule)
            costs.append(time.perf_counter() - t0)
        per_colour.append(np.array(costs))
    t0 = time.perf_counter()
    par.long_pass(st, prior, lay, seed, scan, kernel._rule)
    return per_colour, time.perf_counter() - t0


def build(experiment: int, max_range: float, prior_name: str, resolution: float):
    """Table 6.6's Intel model with readings cut at ``max_range`` metres (``max_usable_range``)."""
    n = round(EXTENT_M / resolution)
    grid = Grid((n, n), resolution, ORIGIN)
    log = read_carmen(intel_log_path(), max_usable_range=max_range)
    scans = log.scans.subsample(pose_fraction=POSE_FRACTION[experiment], beam_step=2)
    rays = raycast(grid, scans)
    if prior_name == "independent":
        prior = IndependentPrior(0.3, grid.num_cells)
    else:
        prior = MRFPrior(grid.shape, psi=0.5, cell_prior=0.3)
    model = OccupancyModel(grid, rays, GaussianRange(3.0), prior)
    model.ray_index()
    return model


def run_config(model, tiles: list[int | None], sweeps: int) -> dict:
    """The serial sweep, then the chromatic sweep with 1 and 2 threads for each tile side (``None``: the
    longest ray's extent), with the tile costs and the scaling model."""
    torch.manual_seed(0)
    serial = CellGibbs(model)
    serial.setup()
    init = serial.initial_params
    serial_s, serial_times = timed_sweeps(serial, sweeps)
    rss_serial = peak_rss_mb()
    print(f"serial CellGibbs: {serial_s:.3f} s/sweep {np.round(serial_times, 3)}; peak RSS {rss_serial:.0f} MiB")
    del serial
    gc.collect()
    release_memory()
    out: dict = {
        "cells": model.num_cells,
        "rays": int(model.rays.num_rays),
        "serial_s_per_sweep": serial_s,
        "serial_sweeps_s": serial_times,
        "peak_rss_serial_mib": rss_serial,
        "tiles": {},
    }
    for T in tiles:
        k = ChromaticCellGibbs(model, tile=T, threads=1)
        k.initial_params = init
        t0 = time.perf_counter()
        k.setup()
        lay = k.layout
        T = lay.T
        setup_s = time.perf_counter() - t0
        per_colour_tiles = np.diff(lay.col_off).tolist()
        long_frac = len(lay.long_cells) / max(len(k._visit), 1)
        res: dict = {
            "setup_s": setup_s,
            "ray_extent": k.ray_extent,
            "tiles_per_colour": per_colour_tiles,
            "long_cell_fraction": long_frac,
        }
        for threads in (1, 2):
            if threads > numba.config.NUMBA_NUM_THREADS:
                continue
            k.threads = threads
            s, times = timed_sweeps(k, sweeps)
            res[f"threads_{threads}_s_per_sweep"] = s
            res[f"threads_{threads}_sweeps_s"] = times
            print(
                f"T {T}: {per_colour_tiles} tiles per colour, long cells {100 * long_frac:.1f} %; "
                f"{threads} thread(s): {s:.3f} s/sweep {np.round(times, 3)} "
                f"(x{serial_s / s:.2f} vs serial); load {loadavg()}",
                flush=True,
            )
        costs, long_s = tile_costs(k)
        res["tile_costs_s"] = [c.tolist() for c in costs]
        res["long_phase_s"] = long_s
        total = sum(float(c.sum()) for c in costs) + long_s
        model_s = {P: sum(lpt_makespan(c, P) for c in costs) + long_s for P in (1, 2, 16, 64)}
        res["model_s_per_sweep"] = model_s
        res["model_speedup_vs_1_thread"] = {P: total / v for P, v in model_s.items()}
        res["parallel_fraction"] = 1.0 - long_s / total
        print(
            f"T {T}: tile costs sum {total - long_s:.3f} s + long {long_s:.3f} s; model sweep on P cores "
            + ", ".join(f"{P}: {v:.3f} s (x{total / v:.2f})" for P, v in model_s.items()),
            flush=True,
        )
        if "threads_2_s_per_sweep" in res:
            res["speedup_2_vs_1_thread"] = res["threads_1_s_per_sweep"] / res["threads_2_s_per_sweep"]
            res["speedup_2_threads_vs_serial"] = serial_s / res["threads_2_s_per_sweep"]
        out["tiles"][str(T)] = res
        del k
        gc.collect()
    out["peak_rss_threads_mib"] = peak_rss_mb()
    print(
        f"peak RSS serial {rss_serial:.0f} MiB, after the threaded sweeps {out['peak_rss_threads_mib']:.0f} MiB "
        f"(x{out['peak_rss_threads_mib'] / rss_serial:.3f})"
    )
    return out


def run_patch(model, prior_names: list[str], sweeps: int) -> dict:
    """3 x 3 patch sweeps under each prior: serial, then chromatic with 1 and 2 threads (module docstring)."""
    out = {}
    for name in prior_names:
        m = copy.copy(model)
        m.prior = prior_by_name(name, model.grid.shape)
        if m.prior.outside_occupancy() != model.prior.outside_occupancy():
            m = OccupancyModel(model.grid, model.rays, model.sensor, m.prior)
        offset = getattr(m.prior, "origin", 0)
        torch.manual_seed(0)
        serial = PatchGibbs(m, (3, 3), offset=offset)
        serial.setup()
        init = serial.initial_params
        serial_s, serial_times = timed_sweeps(serial, sweeps)
        res = {"serial_s_per_sweep": serial_s, "serial_sweeps_s": serial_times}
        print(f"{name}: serial PatchGibbs {serial_s:.3f} s/sweep {np.round(serial_times, 3)}", flush=True)
        del serial
        gc.collect()
        maps = []
        for threads in (1, 2):
            if threads > numba.config.NUMBA_NUM_THREADS:
                continue
            k = ChromaticPatchGibbs(m, (3, 3), offset=offset, threads=threads)
            k.initial_params = init
            k.setup()
            lay = k.layout
            torch.manual_seed(1)
            s, times = timed_sweeps(k, sweeps)
            maps.append(k.state.copy())
            n_long = len(lay.long_anchors)
            res.update(
                {
                    "tile": lay.T,
                    "tiles_per_colour": np.diff(lay.col_off).tolist(),
                    "long_patch_fraction": n_long / max(len(lay.anchors) + n_long, 1),
                    f"threads_{threads}_s_per_sweep": s,
                    f"threads_{threads}_sweeps_s": times,
                }
            )
            print(
                f"{name}: ChromaticPatchGibbs T {lay.T}, {np.diff(lay.col_off).tolist()} tiles per colour, long "
                f"patches {100 * res['long_patch_fraction']:.1f} %; {threads} thread(s): {s:.3f} s/sweep "
                f"(x{serial_s / s:.2f} vs serial); load {loadavg()}",
                flush=True,
            )
            del k
            gc.collect()
        res["same_chain_1_2_threads"] = bool(len(maps) == 2 and np.array_equal(*maps))
        if "threads_2_s_per_sweep" in res:
            res["speedup_2_vs_1_thread"] = res["threads_1_s_per_sweep"] / res["threads_2_s_per_sweep"]
        out[name] = res
    return out


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--experiment", type=int, default=3, choices=sorted(POSE_FRACTION))
    ap.add_argument(
        "--configs",
        default="20:375,5:auto",
        help="max_usable_range (m) : tile sides (cells, '/'-separated; auto = the longest ray), comma separated",
    )
    ap.add_argument("--sweeps", type=int, default=4, help="sweeps per configuration (the first reported apart)")
    ap.add_argument("--prior", default="independent", choices=("independent", "mrf"))
    ap.add_argument("--resolution", type=float, default=0.02)
    ap.add_argument("--patch-range", type=float, default=5.0, help="range (m) of the patch-sweep part; 0: skip")
    ap.add_argument("--patch-priors", nargs="+", default=["patch3:houseexpo", "border:houseexpo"])
    a = ap.parse_args(argv)
    load0 = loadavg()
    payload: dict = {
        "experiment": a.experiment,
        "prior": a.prior,
        "resolution_m": a.resolution,
        "numba_threads_available": numba.config.NUMBA_NUM_THREADS,
        "configs": {},
    }
    for cfg in a.configs.split(","):
        rng, tiles = cfg.split(":")
        sides = [None if x == "auto" else int(x) for x in tiles.split("/")]
        t = time.perf_counter()
        model = build(a.experiment, float(rng), a.prior, a.resolution)
        build_s = time.perf_counter() - t
        print(f"max range {rng} m: {model.rays.num_rays} rays, build {build_s:.1f} s, RSS {rss_mb():.0f} MiB")
        res = run_config(model, sides, a.sweeps)
        res["build_s"] = build_s
        if a.patch_range and float(rng) == a.patch_range:
            res["patch"] = run_patch(model, a.patch_priors, a.sweeps)
        payload["configs"][f"range_{rng}m"] = res
        del model
        release_memory()
    payload["loadavg_start"], payload["loadavg_end"] = load0, loadavg()
    print(f"load {load0} -> {payload['loadavg_end']}")
    print("wrote", write_json("bench_parallel", payload))
    return payload


if __name__ == "__main__":
    main()
