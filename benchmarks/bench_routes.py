"""Exploration routes on large floor plans: the windowed frontier search against the whole-grid one.

``plan_route`` (``ogm_ppl.datasets.stop_and_scan``) chooses each next stop from the frontier clusters near
the known-free cells. It labels the clusters and runs a maximum filter over the known-free cells' window
(grown by the reach), not over the whole grid; the goals are the same (tested). Measured here: the route of
``--poses`` stops (default 40) on the largest IPA plan (office_g, 2258 x 1893 cells) and on two mid-size
plans (IPA NLB, 830 x 991; a HouseExpo plan), at the calibration range (75 cells) and, on the mid-size
plans, a long range (400 cells, where the ray casting of the scans takes most of the time). The baseline is
the whole-grid search (``_next_goal(..., whole_grid=True)``) in the same run. Each route is planned once per
search (seconds to a minute each); the two routes must be identical.
Writes ``out/bench/bench_routes.json``.
"""

from __future__ import annotations

import argparse
import functools
import importlib
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(__file__))
from _common import write_json

from ogm_ppl import Grid
from ogm_ppl.datasets.floorplans import load_plan, training_plans

sas = importlib.import_module("ogm_ppl.datasets.stop_and_scan")

#: (corpus, plan, ranges in cells); plan None: the corpus's largest of its first 20 training plans. office_g runs
#: the calibration range only: at 400 cells its route's ray casting takes minutes, whichever search is used
PLANS = (("ipa", "office_g", (75.0,)), ("ipa", "NLB", (75.0, 400.0)), ("houseexpo", None, (75.0, 400.0)))


def _plan(corpus: str, name: str | None):
    if name is None:
        names = training_plans(corpus)[:20]
        plans = [load_plan(corpus, n) for n in names]
        i = int(np.argmax([p.occupancy.size for p in plans]))
        return names[i], plans[i]
    return name, load_plan(corpus, name)


def _route(truth, grid, F: float, poses: int, whole: bool) -> tuple[np.ndarray, float]:
    original = sas._next_goal
    if whole:
        sas._next_goal = functools.partial(original, whole_grid=True)
    try:
        t = time.perf_counter()
        r = sas.plan_route(truth, grid, max_range_cells=F, num_poses=poses, seed=0)
        return r, time.perf_counter() - t
    finally:
        sas._next_goal = original


def main(poses: int = 40) -> dict:
    rows = []
    _route(np.zeros((20, 20), bool), Grid((20, 20)), 10.0, 2, False)  # compile the ray caster outside the timing
    for corpus, name, ranges in PLANS:
        name, plan = _plan(corpus, name)
        grid = Grid(plan.occupancy.shape, resolution=plan.resolution)
        for F in ranges:
            whole, t_whole = _route(plan.occupancy, grid, F, poses, True)
            win, t_win = _route(plan.occupancy, grid, F, poses, False)
            row = {
                "corpus": corpus,
                "plan": name,
                "shape": list(plan.occupancy.shape),
                "range_cells": F,
                "stops": len(win),
                "whole_grid_s": t_whole,
                "windowed_s": t_win,
                "speedup": t_whole / t_win,
                "identical": bool(np.array_equal(whole, win)),
            }
            rows.append(row)
            print(
                f"{corpus:9s} {name[:28]:28s} {tuple(row['shape'])!s:12s} F {F:5.0f}: {len(win):3d} stops, "
                f"whole grid {t_whole:6.1f} s, windowed {t_win:6.1f} s ({row['speedup']:.2f}x), "
                f"identical {row['identical']}",
                flush=True,
            )
            if not row["identical"]:
                raise SystemExit("the windowed search planned another route than the whole-grid search")
    return {"poses": poses, "rows": rows}


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--poses", type=int, default=40, help="stops per route")
    args = ap.parse_args()
    t0 = time.perf_counter()
    res = main(args.poses)
    res["total_s"] = time.perf_counter() - t0
    print(f"total {res['total_s']:.0f} s; wrote {write_json('bench_routes', res)}")
