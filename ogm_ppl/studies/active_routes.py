r"""Where the rules of an ``active`` experiment send the robot: per-stop step lengths and coverage gains, and the
routes drawn on a plan.

An ``active`` run (``ogm-ppl experiment`` with ``kind = "active"``) records each task
(``tasks/PLAN/METHOD/sSEED.json``): per stop the path length driven so far ``d_i``, the coverage ``c_i`` (share
of the start's free space observed) and the best F1. Pooled over plans and seeds, per method:
:func:`route_stats` gives the stops, the median step ``d_{i+1} - d_i`` (metres), the median coverage gained per
stop ``c_{i+1} - c_i``, the coverage gained per metre ``sum (c_{i+1} - c_i) / sum (d_{i+1} - d_i)``, the share
of steps gaining less than 1 % and, for each level, the median path length to reach that coverage and that best
F1 (infinite, "never", when fewer than half the runs reach it) with how many runs reach it.
:func:`routes_figure` draws each method's stops on a plan (straight segments between them: the robot drives
along planned paths; the segments only show the order).
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from ogm_ppl.studies.errors import StudyInputError

__all__ = ["active_routes", "read_runs", "route_stats", "route_table", "routes_figure"]


def read_runs(out: str | Path, methods: Sequence[str] | None = None) -> dict[str, list[dict]]:
    """The task records of the active run in ``out``, by method (``methods``: these, in this order; default
    every method in the order found); :class:`~ogm_ppl.studies.errors.StudyInputError` names methods with no
    run."""
    out = Path(out)
    runs: dict[str, list[dict]] = {}
    for f in sorted(out.glob("tasks/*/*/s*.json")):
        rec = json.loads(f.read_text())
        if methods is None or rec["method"] in methods:
            runs.setdefault(rec["method"], []).append(rec)
    if methods is not None:
        missing = [m for m in methods if m not in runs]
        if missing:
            raise StudyInputError(f"{out}: no runs of {', '.join(missing)}")
        runs = {m: runs[m] for m in methods}
    return runs


def _path_to(records: list[dict], key: str, level: float) -> float:
    for r in records:
        if r[key] >= level:
            return float(r["path_length"])
    return math.inf


def route_stats(runs: dict[str, list[dict]], levels: Sequence[float]) -> list[dict]:
    """One row per method of ``runs`` (module docstring)."""
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


def route_table(rows: list[dict], levels: Sequence[float]) -> str:
    """The rows of :func:`route_stats` as a Markdown table."""
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


def routes_figure(out: str | Path, runs: dict[str, list[dict]], plan: str, seed: int, path: str | Path) -> Path:
    """Each method's route of ``seed`` on ``plan`` (the run's ``plans/<plan>.npz``) over the plan's truth, one
    panel per method, written to ``path`` (PNG)."""
    from ogm_ppl.grid import Grid
    from ogm_ppl.viz import _plt

    plt = _plt()
    with np.load(Path(out) / "plans" / f"{plan}.npz") as z:
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
    return Path(path)


def active_routes(
    out: str | Path,
    methods: Sequence[str] | None = None,
    levels: Sequence[float] = (0.8, 0.9),
    plan: str | None = None,
    seed: int = 0,
) -> list[dict]:
    """:func:`route_stats` of the active run in ``out`` (``methods``: these, in this order; default all), written
    to ``out/route_stats.json``; with ``plan``, also ``out/routes_<plan>.png`` (:func:`routes_figure` of
    ``seed``). Returns the rows."""
    runs = read_runs(out, methods)
    rows = route_stats(runs, levels)
    from ogm_ppl.io import atomic_write_text

    atomic_write_text(Path(out, "route_stats.json"), json.dumps(rows, indent=1, allow_nan=True))
    if plan:
        routes_figure(out, runs, plan, seed, Path(out) / f"routes_{plan}.png")
    return rows
