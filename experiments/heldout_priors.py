"""Priors judged as predictors of what was not seen (thesis Chapter 5).

On held-out floor plans (never used to learn a table; the buildings of the real logs are excluded from
every training set) we simulate sparse stop-and-scan data, run Gibbs sampling with each prior and score
every cell of the near-mapped mask (cells within 10 cells of a cell some ray reached, Fig. 6.16b) and,
separately, the cells of that mask no ray reached: negative log-likelihood in bits per cell, expected
calibration error, Brier score, best F1, ROC AUC and occupied-class IoU at 0.5 with unknown cells counted
free (the convention of learned map-prediction work). Traditional OGM with our fitted p21 is the baseline
row (unknown cells keep p = 0.5).

    python experiments/heldout_priors.py                 # about 6 min here; writes out/heldout/
    python experiments/heldout_priors.py --plans 2 --sweeps 60 --max-cells 120   # a smoke run
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from ogm_ppl import GaussianRange, Grid, OccupancyModel, raycast
from ogm_ppl.datasets.floorplans import heldout_plans, load_plan
from ogm_ppl.datasets.stop_and_scan import stop_and_scan
from ogm_ppl.inference import CellGibbs, PatchGibbs, RunningStats, evidence_grid, run_gibbs
from ogm_ppl.io import atomic_write_text
from ogm_ppl.metrics import near_mapped_mask, prediction_scores
from ogm_ppl.models import delta_by_name
from ogm_ppl.priors.named import prior_by_name

# (prior, patch): single-cell Gibbs for cell-level priors, 3 x 3 patch Gibbs (the thesis's L = 9) for the
# tile priors, whose sparse tables leave single-cell moves stuck (Section 5.2.2-5.2.3, Table 5.1)
PRIORS = [
    ("independent", 1),
    ("independent:{c}", 1),
    ("mrf:{c}", 1),
    ("border1:{c}", 1),
    ("patch3:{c}", 9),
    ("border:{c}", 9),
]
METRICS = ["nll_bits", "ece", "brier", "best_f1", "auc", "iou"]


def run_plan(plan, args, log) -> list[dict]:
    truth = plan.occupancy
    grid = Grid(truth.shape, resolution=plan.resolution)
    data = stop_and_scan(
        truth,
        grid,
        num_poses=args.poses,
        beams=args.beams,
        max_range_cells=args.range_cells,
        sigma_cells=args.sigma,
        seed=args.seed,
    )
    rays = raycast(grid, data.scans)
    reached = rays.reached().reshape(grid.shape)
    near = near_mapped_mask(reached, 10.0) & plan.known
    unseen = near & ~reached
    masks = {"near": near.ravel(), "unseen": unseen.ravel()}
    rows = []

    def score(name, q, seconds, unknown):
        for mask_name, mask in masks.items():
            s = prediction_scores(q, truth.ravel(), mask=mask, unknown=unknown)
            rows.append({"plan": plan.name, "method": name, "mask": mask_name, "seconds": seconds, **s})

    t0 = time.perf_counter()
    ogm = evidence_grid(rays, delta_by_name("p21"))
    score("traditional OGM (p21)", ogm.probabilities.numpy(), time.perf_counter() - t0, ~ogm.observed.numpy())
    sensor = GaussianRange(args.sigma)
    for spec, L in PRIORS:
        name = spec.format(c=args.corpus)
        prior = prior_by_name(name, grid.shape)
        model = OccupancyModel(grid, rays, sensor, prior)
        stats = RunningStats(model)
        t0 = time.perf_counter()
        kernel = CellGibbs(model) if L == 1 else PatchGibbs(model, (3, 3))
        run_gibbs(kernel, args.sweeps, stats, warmup=args.burn, seed=args.seed, progress=False)
        q = stats.marginals.numpy()
        score(f"Gibbs L={L}, {name}", q, time.perf_counter() - t0, None)
        log(f"  {plan.name}: {name} {time.perf_counter() - t0:.1f} s")
    return rows


def table(rows) -> str:
    methods = list(dict.fromkeys(r["method"] for r in rows))
    out = []
    for mask in ("near", "unseen"):
        out += [
            f"\n**{mask}** cells (mean over plans)\n",
            "| method | " + " | ".join(METRICS) + " | seconds |",
            "|---" * (len(METRICS) + 2) + "|",
        ]
        for m in methods:
            sel = [r for r in rows if r["method"] == m and r["mask"] == mask]
            vals = [np.nanmean([r[k] for r in sel]) for k in METRICS]
            secs = np.mean([r["seconds"] for r in sel])
            out.append(f"| {m} | " + " | ".join(f"{v:.4f}" for v in vals) + f" | {secs:.1f} |")
    return "\n".join(out)


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--corpus", default="houseexpo", help="held-out plans and the tables' corpus")
    ap.add_argument("--plans", type=int, default=6, help="held-out plans to use (the smallest first)")
    ap.add_argument("--max-cells", type=int, default=170, help="skip plans larger than this (either side)")
    ap.add_argument("--poses", type=int, default=3, help="stops of the sparse route")
    ap.add_argument("--beams", type=int, default=90, help="beams per 360-degree scan")
    ap.add_argument("--range-cells", type=float, default=75.0)
    ap.add_argument("--sigma", type=float, default=1.0, help="range noise, cells")
    ap.add_argument("--sweeps", type=int, default=400)
    ap.add_argument("--burn", type=int, default=100)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", default="out/heldout")
    args = ap.parse_args(argv)
    out = Path(args.out)
    names = heldout_plans(args.corpus)
    plans = [load_plan(args.corpus, n) for n in names]
    plans = sorted((p for p in plans if max(p.shape) <= args.max_cells), key=lambda p: p.occupancy.size)
    plans = plans[: args.plans]
    if not plans:
        raise SystemExit(f"no held-out {args.corpus} plan within {args.max_cells} cells")
    print(f"{len(plans)} held-out {args.corpus} plans: " + ", ".join(f"{p.name[:8]} {p.shape}" for p in plans))
    t0 = time.perf_counter()
    rows = []
    for p in plans:
        rows += run_plan(p, args, print)
    md = (
        f"# Priors as predictors of unseen cells ({args.corpus}, {len(plans)} held-out plans)\n\n"
        f"Settings: {vars(args)}; {time.perf_counter() - t0:.0f} s in all.\n" + table(rows) + "\n"
    )
    atomic_write_text(out / "heldout_priors.md", md)
    atomic_write_text(out / "heldout_priors.json", json.dumps({"settings": vars(args), "rows": rows}, indent=1))
    print(md)
    return {"rows": rows}


if __name__ == "__main__":
    main()
