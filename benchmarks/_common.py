"""Shared helpers of the benchmarks: timing, peak memory, JSON output stamped with its provenance."""

from __future__ import annotations

import json
import resource
import time
from pathlib import Path

import numpy as np

OUT = Path(__file__).resolve().parent.parent / "out" / "bench"


def best_time(fn, repeat: int = 5, warmup: int = 1) -> float:
    """The best wall time of ``repeat`` calls after ``warmup`` calls (seconds)."""
    for _ in range(warmup):
        fn()
    best = float("inf")
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def peak_rss_mb() -> float:
    """Peak resident set size of this process so far, in MiB (Linux reports KiB)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def provenance(command: str | None = None) -> dict:
    """The provenance block (:func:`ogm_ppl.provenance.provenance`): command (default this process's
    ``python benchmarks/bench_NAME.py ...``), commit, machine, date."""
    from ogm_ppl.provenance import provenance as _provenance

    return _provenance(command)


def write_json(name: str, payload: dict) -> Path:
    """Write ``payload`` to ``out/bench/NAME.json`` atomically, under a ``"provenance"`` key
    (:func:`provenance`: command, commit, machine, date) that the docs' tables print under each table."""
    from ogm_ppl.io import atomic_write_text

    stamped = {"provenance": provenance(), **payload}
    return atomic_write_text(OUT / f"{name}.json", json.dumps(stamped, indent=2))


def sparse_scene(
    n: int,
    poses: int,
    walls: int,
    seed: int = 0,
    res: float = 0.05,
    max_range_cells: int = 75,
    sigma_cells: float = 3.0,
    beams: int = 720,
):
    """An ``n x n`` map with a border and ``walls`` random wall segments, scanned from ``poses`` random
    free cells with ``beams`` beams each (simulated, seeded): most beams are max-range readings."""
    from ogm_ppl import Grid
    from ogm_ppl.datasets import simulate_scans

    rng = np.random.default_rng(seed)
    truth = np.zeros((n, n), dtype=bool)
    truth[0, :] = truth[-1, :] = truth[:, 0] = truth[:, -1] = True
    for _ in range(walls):
        r, c = rng.integers(5, n - 5, 2)
        length = int(rng.integers(20, 80))
        if rng.random() < 0.5:
            truth[r, c : c + length] = True
        else:
            truth[r : r + length, c] = True
    grid = Grid((n, n), resolution=res)
    free = np.argwhere(~truth)
    pick = free[rng.choice(len(free), poses, replace=False)]
    xy = np.c_[(pick[:, 1] + 0.5) * res, (pick[:, 0] + 0.5) * res, rng.uniform(-np.pi, np.pi, poses)]
    angles = np.arange(beams) * (2 * np.pi / beams)
    return grid, simulate_scans(grid, truth, xy, angles, max_range_cells * res, sigma_cells, seed)
