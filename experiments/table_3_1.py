"""Table 3.1: average summed KL between each mapping algorithm and the exact posterior, 1000 1D datasets.

Each dataset: a wall at f = 20, sigma = 2 cells, one to eight readings (uniform), the robot in cell 0 and
K = 30 latent cells (the thesis does not state K); uniform prior. Rows: traditional OGM (Hähnel), optimised
traditional OGM (our shipped p21 and optimised Moravec, fitted for F = 75, wall 60, sigma 3 as in Section
2.5), online patch maps (forward sensor model) L = 1, 3, 5, offline patch maps L = 1, 3, 5 (MAP reference),
offline with overlap L = 3, 5, and single-cell Gibbs with 10^5 sweeps. Patch boundaries start before cell 1
(as in the thesis).

    python experiments/table_3_1.py [--datasets 1000] [--gibbs-sweeps 100000] [--cells 30]

Writes out/experiments/table_3_1.{md,json}.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
import torch
from tqdm import tqdm

from ogm_ppl import GaussianRange, OccupancyModel, raycast
from ogm_ppl.datasets import toy_1d
from ogm_ppl.inference import evidence_grid
from ogm_ppl.inference.exact import pose_constrained_1d
from ogm_ppl.inference.mcmc.gibbs import CellGibbs
from ogm_ppl.inference.patch_map import offline_patch_map, online_patch_map, reference_map
from ogm_ppl.io import atomic_write_text
from ogm_ppl.metrics import kl_divergence
from ogm_ppl.models import delta_by_name
from ogm_ppl.priors import IndependentPrior

torch.set_default_dtype(torch.float64)

THESIS = {
    "traditional OGM (Hähnel)": 6.7870,
    "traditional OGM, optimised (p21)": 0.2509,
    "online patch map L=1": 0.5297,
    "online patch map L=3": 0.3100,
    "online patch map L=5": 0.2290,
    "offline patch map L=1": 0.2834,
    "offline patch map L=3": 0.0749,
    "offline patch map L=5": 0.0274,
    "offline, overlap L=3": 0.0287,
    "offline, overlap L=5": 0.0038,
    "Gibbs": 3.72e-5,
}


def datasets(n: int, cells: int, seed: int = 0):
    rng = np.random.default_rng(seed)
    for _ in range(n):
        yield np.clip(np.rint(rng.normal(20.0, 2.0, int(rng.integers(1, 9)))), 0, cells)


def run(num_datasets: int = 1000, gibbs_sweeps: int = 100_000, cells: int = 30, seed: int = 0, progress=True) -> dict:
    kls: dict[str, list[float]] = {}
    t0 = time.perf_counter()
    deltas = {
        "traditional OGM (Hähnel)": delta_by_name("haehnel"),
        "traditional OGM, optimised (p21)": delta_by_name("p21"),
        "traditional OGM, optimised (Moravec)": delta_by_name("moravec_opt"),
    }
    for d, z in enumerate(tqdm(datasets(num_datasets, cells, seed), total=num_datasets, disable=not progress)):
        toy = toy_1d(num_cells=cells + 1, wall=20, readings=z)
        rays = raycast(toy.grid, toy.scans)
        model = OccupancyModel(toy.grid, rays, GaussianRange(2.0), IndependentPrior(0.5, cells + 1))
        exact = pose_constrained_1d(model).marginals[1:]

        def score(name, q, exact=exact):
            kls.setdefault(name, []).append(float(kl_divergence(exact, q[1:].clamp(1e-12, 1 - 1e-12))))

        for name, delta in deltas.items():
            score(name, evidence_grid(rays, delta).probabilities)
        ref = reference_map(model)
        for L in (1, 3, 5):
            score(f"online patch map L={L}", online_patch_map(model, L, offset=1).marginals)
            score(f"offline patch map L={L}", offline_patch_map(model, L, offset=1, reference=ref).marginals)
        for L in (3, 5):
            score(f"offline, overlap L={L}", offline_patch_map(model, L, overlap=True, reference=ref).marginals)
        if gibbs_sweeps:
            kernel = CellGibbs(model, init="ogm")
            kernel.setup()
            score("Gibbs", kernel.run_marginals(gibbs_sweeps, seed=seed * 100_003 + d))
    rows = {
        k: {"mean": float(np.mean(v)), "median": float(np.median(v)), "thesis": THESIS.get(k)} for k, v in kls.items()
    }
    return {
        "datasets": num_datasets,
        "cells": cells,
        "gibbs_sweeps": gibbs_sweeps,
        "seed": seed,
        "rows": rows,
        "seconds": time.perf_counter() - t0,
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--datasets", type=int, default=1000)
    ap.add_argument("--gibbs-sweeps", type=int, default=100_000)
    ap.add_argument("--cells", type=int, default=30)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    res = run(args.datasets, args.gibbs_sweeps, args.cells, args.seed)
    lines = ["| algorithm | mean summed KL (ours) | thesis |", "|---|---|---|"]
    for k, v in res["rows"].items():
        th = "" if v["thesis"] is None else f"{v['thesis']:.4g}"
        lines.append(f"| {k} | {v['mean']:.4g} | {th} |")
    lines.append("")
    lines.append(
        f"{res['datasets']} datasets, K = {res['cells']} latent cells, Gibbs {res['gibbs_sweeps']:,} sweeps; "
        f"{res['seconds']:.0f} s."
    )
    md = "\n".join(lines)
    out = Path(__file__).resolve().parent.parent / "out" / "experiments"
    atomic_write_text(out / "table_3_1.md", md)
    atomic_write_text(out / "table_3_1.json", json.dumps(res, indent=2))
    print(md)


if __name__ == "__main__":
    main()
