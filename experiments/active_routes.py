r"""Where the rules of an ``active`` experiment send the robot: per-stop step lengths and coverage gains, and
the routes drawn on a plan.

    python experiments/active_routes.py out/active_medium                      # every method
    python experiments/active_routes.py out/active_medium --methods frontier patch3-ig patch3-cov-per-m \
        --plan p00 --levels 0.8 0.9

Reads the per-task records an ``active`` run wrote (``tasks/PLAN/METHOD/sSEED.json``) and prints, per method,
pooled over plans and seeds: stops, the median step (metres driven between two stops), the median coverage
gained per stop (share of the free space), the coverage gained per metre driven (total over all steps),
the share of steps that gained less than 1 % coverage, and the path length to each ``--levels`` of coverage and
of best F1 (median over runs; "never" when fewer than half reach it), with how many runs reach it. Writes the
same as ``route_stats.json`` and, with ``--plan``, ``routes_PLAN.png``: the plan's truth and each method's stops
and straight segments between them (the robot drives along planned paths; the segments only show the order).
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

import numpy as np


def _runs(out: Path, methods: list[str] | None) -> dict[str, list[dict]]:
    runs: dict[str, list[dict]] = {}
    for f in sorted(out.glob("tasks/*/*/s*.json")):
        rec = json.loads(f.read_text())
        if methods is None or rec["method"] in methods:
            runs.setdefault(rec["method"], []).append(rec)
    if methods is not None:
        missing = [m for m in methods if m not in runs]
        if missing:
            raise SystemExit(f"{out}: no runs of {', '.join(missing)}")
        runs = {m: runs[m] for m in methods}
    return runs


def _path_to(records: list[dict], key: str, level: float) -> float:
    for r in records:
        if r[key] >= level:
            return float(r["path_length"])
    return math.inf


def stats(runs: dict[str, list[dict]], levels: list[float]) -> list[dict]:
    """One row per method (module docstring)."""
    rows = []
    for name, rs in runs.items():
        steps, gains = [], []
        for r in rs:
            d = np.array([s["path_length"] for s in r["records"]])
            c = np.array([s["coverage"] for s in r["records"]])
            steps += np.diff(d).tolist()
            gains += np.diff(c).tolist()
        steps_a, gains_a = np.array(steps), np.array(gains)
        row = {
            "method": name,
            "runs": len(rs),
            "stops": int(sum(len(r["records"]) for r in rs)),
            "median_step_m": float(np.median(steps_a)),
            "median_gain_per_stop": float(np.median(gains_a)),
            "gain_per_metre": float(gains_a.sum() / steps_a.sum()),
            "share_small_steps": float(np.mean(gains_a < 0.01)),
        }
        for key in ("coverage", "f1"):
            for lv in levels:
                p = np.array([_path_to(r["records"], key, lv) for r in rs])
                row[f"path_to_{key}_{lv:g}"] = float(np.median(p))
                row[f"reached_{key}_{lv:g}"] = int(np.isfinite(p).sum())
        rows.append(row)
    return rows


def _fmt(x: float) -> str:
    return "never" if math.isinf(x) else f"{x:.2f}"


def table(rows: list[dict], levels: list[float]) -> str:
    head = ["method", "runs", "stops", "median step m", "median cov. gain / stop", "cov. gain / m", "steps < 1 %"]
    head += [f"path to {k} {lv:g}" for k in ("cov.", "F1") for lv in levels]
    lines = ["| " + " | ".join(head) + " |", "|---" * len(head) + "|"]
    for r in rows:
        cells = [r["method"], str(r["runs"]), str(r["stops"]), f"{r['median_step_m']:.2f}"]
        cells += [f"{r['median_gain_per_stop']:.3f}", f"{r['gain_per_metre']:.3f}", f"{r['share_small_steps']:.2f}"]
        for key in ("coverage", "f1"):
            for lv in levels:
                cells.append(f"{_fmt(r[f'path_to_{key}_{lv:g}'])} ({r[f'reached_{key}_{lv:g}']}/{r['runs']})")
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def routes_figure(out: Path, runs: dict[str, list[dict]], plan: str, seed: int, path: Path) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ogm_ppl.grid import Grid

    with np.load(out / "plans" / f"{plan}.npz") as z:
        truth, res = z["truth"].astype(bool), float(z["resolution"])
    grid = Grid(truth.shape, resolution=res)
    n = len(runs)
    ncol = min(n, 4)
    nrow = -(-n // ncol)
    fig, axes = plt.subplots(nrow, ncol, figsize=(3.4 * ncol, 3.7 * nrow), squeeze=False)
    for ax in axes.ravel()[n:]:
        ax.axis("off")
    for ax, (name, rs) in zip(axes.ravel(), runs.items()):
        r = next((x for x in rs if x["plan_id"] == plan and x["seed"] == seed), None)
        ax.imshow(truth, cmap="gray_r", vmin=0, vmax=2.5, interpolation="nearest")
        if r is not None:
            xy = np.array(r["route"])[:, :2]
            rc = grid.world_to_cell(xy)
            ax.plot(rc[:, 1], rc[:, 0], "-o", ms=3, lw=1)
            ax.plot(rc[0, 1], rc[0, 0], "g*", ms=10)
            p90 = r["path_to"]["coverage"]
            ax.set_title(f"{name}\n{len(xy)} stops, 90 % cov. at {_fmt(p90)} m", fontsize=8)
        ax.set_xticks([])
        ax.set_yticks([])
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("out", type=Path, help="the --out directory of an active experiment")
    ap.add_argument("--methods", nargs="+", default=None, help="these methods, in this order (default all)")
    ap.add_argument("--levels", nargs="+", type=float, default=[0.8, 0.9], help="coverage / F1 levels")
    ap.add_argument("--plan", default=None, help="draw the routes on this plan (e.g. p00)")
    ap.add_argument("--seed", type=int, default=0, help="the spec seed of the routes drawn")
    args = ap.parse_args(argv)
    runs = _runs(args.out, args.methods)
    rows = stats(runs, args.levels)
    print(table(rows, args.levels))
    (args.out / "route_stats.json").write_text(json.dumps(rows, indent=1, allow_nan=True))
    if args.plan:
        print(routes_figure(args.out, runs, args.plan, args.seed, args.out / f"routes_{args.plan}.png"))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
