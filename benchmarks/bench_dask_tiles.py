"""Chromatic tile sweeps on dask (:class:`~ogm_ppl.inference.mcmc.dask_tiles.DaskTileGibbs`) on Intel at 2 cm,
and what a 1 km^2 map at 5 cm (4 x 10^8 cells) would cost on N workers.

The model is ``bench_parallel.py``'s: the Intel Lab log, 30 m x 30 m at 2 cm (2.25 M cells), half the beams,
``--experiment`` 3 (a tenth of the poses), readings cut at ``--range`` metres, ``GaussianRange(3 cells)``, an
independent prior (``lambda = 0.3``) or ``--prior mrf``; the tile side is the longest ray's extent, so every cell
is short. After a warm-up sweep of each (numba's compilation, the scatter):

* the serial single-cell sweep (``CellGibbs``), the baseline of the ratios;
* the threaded chromatic sweep (``ChromaticCellGibbs``) with 1 and 2 threads;
* the dask sweep on a ``LocalCluster`` of ``--workers`` single-threaded worker processes, checked to be the
  threaded chain bit for bit over the timed sweeps;
* each task's cost, measured alone in this process: the rebuild of its hits and sums from the window's values
  and its tile's updates (``run_tile``), with the bytes it moves (window bits in, tile values out) and the
  bytes of its sub-problem.

**The paper model** for ``--big-cells`` cells at ``--big-resolution`` with rays of ``--big-range`` metres: tiles
of side ``T = range / resolution`` (every cell short), ``n = cells / T^2`` tiles, ``n / 4`` per colour. A task's
time is the measured time per visited cell times ``T^2`` (the measured map's density of ray entries per cell
is assumed; a denser log scales it), its transfer ``(3T)^2 / 8 + T^2`` bytes at ``--bandwidth`` bytes/s, and the
driver's cost per task (``--driver-us``, the scheduler's per-task overhead measured here when left unset). On N
workers a colour phase takes ``ceil((n / 4) / N)`` rounds of (task + transfer), or the driver's serial work if
that is longer; a sweep is four phases. The driver holds the whole map and its kept state (``m``, ``d``, the
counts of infinite terms: 13 bytes a cell) and the rays' hits (16 bytes a ray).

The machine may be shared (the load average is printed). Writes ``out/bench/bench_dask_tiles.json``; about
3 minutes on 2 cores.
"""

from __future__ import annotations

import argparse
import logging
import math
import os
import sys
import time

os.environ.setdefault("NUMBA_NUM_THREADS", "2")

import numba
import numpy as np
import torch

sys.path.insert(0, os.path.dirname(__file__))
from _common import write_json
from bench_parallel import build, timed_sweeps
from bench_table_6_6 import POSE_FRACTION, loadavg

from ogm_ppl.inference._kernels import cell_sweep as cs
from ogm_ppl.inference.mcmc import CellGibbs
from ogm_ppl.inference.mcmc.dask_tiles import DaskTileGibbs, _tile_draws, _window, run_tile
from ogm_ppl.inference.mcmc.parallel import ChromaticCellGibbs

torch.set_default_dtype(torch.float64)


def task_costs(kernel: DaskTileGibbs) -> list[dict]:
    """Each sub-problem's rebuild and sweep seconds (single thread, in this process) and bytes."""
    out = []
    cols = kernel.model.grid.cols
    m = kernel.state
    for p in kernel.problems:
        packed = np.packbits(m[p.window_of(cols)])
        run_tile(p, packed, 1)  # compiled for this bundle type
        t0 = time.perf_counter()
        w = np.unpackbits(packed, count=p.window_cells)
        st = cs.cell_state(w, p.offsets, p.cells, p.c_off, p.c_ray, p.c_kappa, p.ll, p.bits)
        t1 = time.perf_counter()
        order, u = _tile_draws(p.visit, p.scan, np.uint64(12345), p.t)
        cs.sweep(st, order, p.prior, u, p.update)
        t2 = time.perf_counter()
        out.append(
            {
                "visited": len(p.visit),
                "window_cells": p.window_cells,
                "ray_entries": len(p.cells),
                "rebuild_s": t1 - t0,
                "sweep_s": t2 - t1,
                "bytes_in": packed.nbytes,
                "bytes_out": len(p.visit),
                "problem_bytes": p.nbytes(),
            }
        )
    return out


def driver_costs(kernel: DaskTileGibbs, client, repeat: int = 3) -> dict:
    """The driver's work, measured apart: packing a window's values (seconds per window cell), comparing a
    tile's returned values with the map (per visited cell), and dask's round trip of a task that does
    nothing (``client.map`` of 200 no-op tasks, gathered; seconds per task)."""
    cols = kernel.model.grid.cols
    m = kernel.state
    grid = m.reshape(kernel.layout.rows, cols)
    visits = [p.window_of(cols)[p.visit] for p in kernel.problems]
    n_window = sum(p.window_cells for p in kernel.problems)
    n_visit = sum(len(v) for v in visits)
    pack = unpack = 1e9
    for _ in range(repeat):
        t0 = time.perf_counter()
        for p in kernel.problems:
            np.packbits(_window(grid, p))
        t1 = time.perf_counter()
        for v in visits:
            vals = m[v]
            np.nonzero(vals != m[v])
        t2 = time.perf_counter()
        pack, unpack = min(pack, t1 - t0), min(unpack, t2 - t1)
    n = 200
    client.gather(client.map(_noop, range(n), pure=False))  # warm
    t0 = time.perf_counter()
    client.gather(client.map(_noop, range(n), pure=False))
    sched = (time.perf_counter() - t0) / n
    return {"pack_s_per_window_cell": pack / n_window, "apply_s_per_cell": unpack / n_visit, "task_round_trip_s": sched}


def _noop(i: int) -> int:
    return i


def paper_model(per_cell_s: float, driver: dict, cells: float, T: int, bandwidth: float, workers) -> dict:
    """The sweep time of the paper model (module docstring) on each number of workers, with one tile a task
    (``sweep_s``) and with the tiles of a colour dealt into one task per worker (``sweep_s_batched``)."""
    n = math.ceil(cells / T**2)
    per_colour = math.ceil(n / 4)
    task_s = per_cell_s * T**2
    bytes_task = (3 * T) ** 2 / 8 + T**2
    transfer_s = bytes_task / bandwidth
    data_s = driver["pack_s_per_window_cell"] * (3 * T) ** 2 + driver["apply_s_per_cell"] * T**2
    trip = driver["task_round_trip_s"]
    out = {
        "tiles": n,
        "tiles_per_colour": per_colour,
        "task_s": task_s,
        "bytes_per_task": bytes_task,
        "transfer_s_per_task": transfer_s,
        "driver_s_per_tile": data_s + trip,
        "bytes_per_sweep": bytes_task * n,
        "driver_memory_gib": (13 * cells) / 2**30,
        "sweep_s": {},
        "sweep_s_batched": {},
    }
    for N in workers:
        rounds = math.ceil(per_colour / N)
        work = rounds * (task_s + transfer_s)
        out["sweep_s"][str(N)] = 4 * max(work, per_colour * (data_s + trip))
        out["sweep_s_batched"][str(N)] = 4 * max(work, per_colour * data_s + min(N, per_colour) * trip)
    out["serial_sweep_s"] = per_cell_s * cells
    return out


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--experiment", type=int, default=3, choices=sorted(POSE_FRACTION))
    ap.add_argument("--range", type=float, default=5.0, help="max_usable_range in metres (tiles follow it)")
    ap.add_argument("--prior", default="independent", choices=("independent", "mrf"))
    ap.add_argument("--resolution", type=float, default=0.02)
    ap.add_argument("--sweeps", type=int, default=4, help="timed sweeps per kernel (the first reported apart)")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--big-cells", type=float, default=4e8)
    ap.add_argument("--big-resolution", type=float, default=0.05)
    ap.add_argument("--big-range", type=float, default=20.0)
    ap.add_argument("--bandwidth", type=float, default=1.25e9, help="bytes/s between driver and workers (10 GbE)")
    ap.add_argument(
        "--driver-us", type=float, default=None, help="dask's round trip per task in us (default: measured)"
    )
    a = ap.parse_args(argv)
    from distributed import Client, LocalCluster

    load0 = loadavg()
    t = time.perf_counter()
    model = build(a.experiment, a.range, a.prior, a.resolution)
    build_s = time.perf_counter() - t
    print(f"Intel {a.resolution * 100:.0f} cm, range {a.range} m: {model.num_cells} cells, {model.rays.num_rays} rays")
    torch.manual_seed(0)
    serial = CellGibbs(model)
    serial.setup()
    init = serial.initial_params
    serial_s, serial_times = timed_sweeps(serial, a.sweeps)
    print(f"serial CellGibbs: {serial_s:.3f} s/sweep")
    del serial
    res: dict = {"cells": model.num_cells, "rays": int(model.rays.num_rays), "build_s": build_s}
    res["serial_s_per_sweep"], res["serial_sweeps_s"] = serial_s, serial_times

    threaded = ChromaticCellGibbs(model, threads=1)
    threaded.initial_params = init
    threaded.setup()
    res["tile"] = T = threaded.layout.T
    res["tiles_per_colour"] = np.diff(threaded.layout.col_off).tolist()
    for threads in (1, 2):
        if threads > numba.config.NUMBA_NUM_THREADS:
            continue
        threaded.set_state(init["m"])
        threaded.threads = threads
        torch.manual_seed(1)
        s, times = timed_sweeps(threaded, a.sweeps)
        res[f"threads_{threads}_s_per_sweep"] = s
        print(f"ChromaticCellGibbs T {T}, {threads} thread(s): {s:.3f} s/sweep (x{serial_s / s:.2f} vs serial)")
    threaded.set_state(init["m"])
    torch.manual_seed(2)
    p = threaded.current_params()
    ref = []
    for _ in range(a.sweeps):
        p = threaded.sample(p)
        ref.append(threaded.state.copy())

    cluster = LocalCluster(
        n_workers=a.workers, threads_per_worker=1, processes=True, dashboard_address=None, silence_logs=logging.ERROR
    )
    client = Client(cluster)
    t = time.perf_counter()
    dask = DaskTileGibbs(model, client=client)
    dask.initial_params = init
    dask.setup()
    _ = dask.problems
    res["problems_s"] = time.perf_counter() - t
    t = time.perf_counter()
    dask._scatter()
    res["scatter_s"] = time.perf_counter() - t
    dask.set_state(init["m"])
    torch.manual_seed(3)
    dask._sweep()  # warm-up: the workers compile the kernels
    dask.set_state(init["m"])
    torch.manual_seed(2)
    p = dask.current_params()
    times, same, phases = [], True, []
    for i in range(a.sweeps):
        t = time.perf_counter()
        p = dask.sample(p)
        times.append(time.perf_counter() - t)
        phases.append(dask.last_sweep["phase_s"])
        same &= bool(np.array_equal(dask.state, ref[i]))
    res["dask_s_per_sweep"] = float(np.mean(times))
    res["dask_sweeps_s"] = times
    res["dask_phase_s"] = phases
    res["dask_equals_threaded"] = same
    res["dask_bytes_sent"] = dask.last_sweep["bytes_sent"]
    res["dask_bytes_received"] = dask.last_sweep["bytes_received"]
    print(
        f"DaskTileGibbs {a.workers} workers: {res['dask_s_per_sweep']:.3f} s/sweep "
        f"(x{serial_s / res['dask_s_per_sweep']:.2f} vs serial); same chain as the threaded one: {same}; "
        f"{res['dask_bytes_sent'] / 1e6:.2f} MB sent, "
        f"{res['dask_bytes_received'] / 1e6:.2f} MB back a sweep"
    )
    batch = math.ceil(max(res["tiles_per_colour"]) / a.workers)
    with DaskTileGibbs(model, client=client, tiles_per_task=batch) as batched:
        batched.initial_params = init
        batched.setup()
        batched._scatter()
        torch.manual_seed(3)
        batched._sweep()
        batched.set_state(init["m"])
        torch.manual_seed(2)
        p = batched.current_params()
        times, same_b = [], True
        for i in range(a.sweeps):
            t = time.perf_counter()
            p = batched.sample(p)
            times.append(time.perf_counter() - t)
            same_b &= bool(np.array_equal(batched.state, ref[i]))
    res["batched_tiles_per_task"] = batch
    res["batched_s_per_sweep"] = float(np.mean(times))
    res["batched_equals_threaded"] = same_b
    print(
        f"DaskTileGibbs {a.workers} workers, {batch} tiles a task: {res['batched_s_per_sweep']:.3f} s/sweep "
        f"(x{serial_s / res['batched_s_per_sweep']:.2f} vs serial); same chain: {same_b}"
    )
    costs = task_costs(dask)
    res["driver"] = driver = driver_costs(dask, client)
    if a.driver_us is not None:
        driver["task_round_trip_s"] = a.driver_us * 1e-6
    dask.close()
    client.close()
    cluster.close()
    visited = sum(c["visited"] for c in costs)
    compute = sum(c["rebuild_s"] + c["sweep_s"] for c in costs)
    res["tasks"] = costs
    res["task_compute_s_per_sweep"] = compute
    res["rebuild_fraction"] = sum(c["rebuild_s"] for c in costs) / compute
    res["per_cell_s"] = per_cell = compute / visited
    print(
        f"tasks: {len(costs)}, compute {compute:.3f} s a sweep ({100 * res['rebuild_fraction']:.0f} % rebuilding), "
        f"{per_cell * 1e9:.0f} ns per visited cell; driver: packing {driver['pack_s_per_window_cell'] * 1e9:.2f} ns "
        f"a window cell, applying {driver['apply_s_per_cell'] * 1e9:.2f} ns a tile cell, "
        f"{driver['task_round_trip_s'] * 1e3:.2f} ms a task's round trip"
    )
    big_T = round(a.big_range / a.big_resolution)
    res["paper"] = paper = paper_model(per_cell, driver, a.big_cells, big_T, a.bandwidth, (1, 16, 64, 256))
    print(
        f"paper model, {a.big_cells:.1e} cells at {a.big_resolution * 100:.0f} cm, T {big_T}: {paper['tiles']} tiles, "
        f"task {paper['task_s']:.3f} s, {paper['bytes_per_task'] / 1e3:.0f} kB a task, serial sweep "
        f"{paper['serial_sweep_s']:.0f} s; sweep on N workers "
        + ", ".join(f"{N}: {v:.1f} s" for N, v in paper["sweep_s"].items())
        + "; one task a worker a phase: "
        + ", ".join(f"{N}: {v:.1f} s" for N, v in paper["sweep_s_batched"].items())
        + f"; driver state {paper['driver_memory_gib']:.1f} GiB"
    )
    payload = {
        "experiment": a.experiment,
        "range_m": a.range,
        "prior": a.prior,
        "resolution_m": a.resolution,
        "workers": a.workers,
        "bandwidth_bytes_s": a.bandwidth,
        "result": res,
        "loadavg_start": load0,
        "loadavg_end": loadavg(),
    }
    print(f"load {load0} -> {payload['loadavg_end']}")
    print("wrote", write_json("bench_dask_tiles", payload))
    return payload


if __name__ == "__main__":
    main()
