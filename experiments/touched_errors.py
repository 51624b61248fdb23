"""Where maps' errors on the touched cells of an experiment lie, against the benchmark's walls.

For an experiment folder written by ``ogm-ppl experiment`` on a log (the truth is the benchmark map:
traditional OGM from all readings), each dataset (a sparsity) and algorithm: at the algorithm's best
touched-only threshold (``maps/D/A.json``), the share of the touched benchmark-occupied cells called
occupied by depth into the wall (chessboard cells from the nearest touched benchmark-free cell, 1, 2, 3+),
the walls missed (false negatives), and the false positives on touched cells by their chessboard distance to
the nearest benchmark-occupied cell (1: the cell in front of a wall face; 2-3; 4 and more: free space).

``--out DIR`` writes ``DIR/touched_errors.json`` (every count, the touched best F1 and threshold) and
``DIR/touched_errors.png`` (one panel per dataset: each algorithm's walls missed and false positives by
distance, stacked). Results page, Intel: "Where the touched cells differ".

    python experiments/touched_errors.py out/experiments/intel_guide ogm guide-he-ipa --out out/touched
    python experiments/touched_errors.py out/experiments/intel_6_5 ogm dd-L1 --datasets intel-pf1
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np
from scipy import ndimage

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from ogm_ppl.io import atomic_write, atomic_write_text

FP_BINS = ("1", "2-3", "4+")


def touched_errors(folder: Path, dataset: str, algorithm: str) -> dict:
    """The counts above for one dataset and algorithm of the experiment in ``folder``; refused unless they give
    the touched best F1 the experiment recorded (the same cells, truth and threshold)."""
    ev = np.load(folder / "datasets" / f"{dataset}.eval.npz")
    truth, touched = ev["truth"].astype(bool), ev["touched"].astype(bool)
    q = np.load(folder / "maps" / dataset / f"{algorithm}.npz")["marginals"]
    scores = json.loads((folder / "maps" / dataset / f"{algorithm}.json").read_text())["touched"]
    thr = scores["threshold"]
    pred = q > thr
    free_t = ~truth & touched
    depth = ndimage.distance_transform_cdt(~free_t, metric="chessboard")
    dist = ndimage.distance_transform_cdt(~truth, metric="chessboard")
    occ = truth & touched
    by_depth = {
        int(d): {
            "cells": int((occ & (np.minimum(depth, 3) == d)).sum()),
            "called_occupied": float(pred[occ & (np.minimum(depth, 3) == d)].mean()),
        }
        for d in (1, 2, 3)
        if (occ & (np.minimum(depth, 3) == d)).any()
    }
    fp = pred & free_t
    by_dist = np.bincount(np.minimum(dist[fp], 6), minlength=7)[1:]
    tp, fn = int((pred & occ).sum()), int((~pred & occ).sum())
    f1 = 2 * tp / max(2 * tp + fn + int(fp.sum()), 1)
    if abs(f1 - scores["best_f1"]) > 1e-9:  # these counts must be the experiment's own at its threshold
        raise SystemExit(
            f"{folder}: {dataset}/{algorithm}: the touched cells counted here give F1 {f1:.6f} at threshold {thr}, "
            f"the experiment recorded {scores['best_f1']:.6f}"
        )
    return {
        "threshold": thr,
        "touched_best_f1": scores["best_f1"],
        "walls_by_depth": by_depth,
        "false_positives": int(fp.sum()),
        "fp_by_distance_1_to_6plus": by_dist.tolist(),
        "fp_binned": dict(zip(FP_BINS, (int(by_dist[0]), int(by_dist[1:3].sum()), int(by_dist[3:].sum())))),
        "true_positives": tp,
        "false_negatives": fn,
    }


def figure(result: dict, path: Path) -> None:
    """One panel per dataset: per algorithm a bar of walls missed and one of false positives, stacked by
    distance to the nearest benchmark wall."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    data = result["datasets"]
    fig, axes = plt.subplots(1, len(data), figsize=(4.2 * len(data), 1.4 + 0.6 * len(result["algorithms"])))
    axes = np.atleast_1d(axes)
    colours = ("#c0392b", "#e67e22", "#f4d03f")
    for ax, (ds, algs) in zip(axes, data.items()):
        names = list(algs)
        y = np.arange(len(names))
        ax.barh(y + 0.2, [algs[a]["false_negatives"] for a in names], 0.38, color="#2c3e50", label="walls missed")
        left = np.zeros(len(names))
        for b, c in zip(FP_BINS, colours):
            v = np.array([algs[a]["fp_binned"][b] for a in names], dtype=float)
            ax.barh(y - 0.2, v, 0.38, left=left, color=c, label=f"false positive, {b} from a wall")
            left += v
        ax.set_yticks(y, [f"{a}\nF1 {algs[a]['touched_best_f1']:.3f}" for a in names], fontsize=8)
        ax.invert_yaxis()
        ax.set_title(ds, fontsize=10)
        ax.set_xlabel("touched cells")
    handles, labels = axes[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=4, fontsize=8, frameon=False)
    fig.suptitle("Touched-cell errors at each map's best touched threshold", fontsize=10)
    fig.tight_layout(rect=(0, 0.1, 1, 1))
    with atomic_write(path) as f:
        fig.savefig(f, format="png", dpi=110)
    plt.close(fig)


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("folder", type=Path, help="an experiment's output folder (ogm-ppl experiment --out)")
    ap.add_argument("algorithm", nargs="+")
    ap.add_argument("--datasets", nargs="+", default=None, help="default: every dataset of the folder")
    ap.add_argument("--out", type=Path, default=None, help="write touched_errors.json and .png here")
    args = ap.parse_args(argv)
    if not (args.folder / "datasets").is_dir():
        raise SystemExit(f"{args.folder}: not an experiment folder (no datasets/)")
    datasets = args.datasets or sorted(
        p.name[: -len(".eval.npz")] for p in (args.folder / "datasets").glob("*.eval.npz")
    )
    if not datasets:
        raise SystemExit(f"{args.folder}: no scored dataset (datasets/*.eval.npz)")
    for d in datasets:
        for a in args.algorithm:
            if not (args.folder / "maps" / d / f"{a}.npz").is_file():
                raise SystemExit(f"{args.folder}: no map of algorithm {a!r} on dataset {d!r}")
    result = {
        "experiment": str(args.folder),
        "algorithms": args.algorithm,
        "datasets": {d: {a: touched_errors(args.folder, d, a) for a in args.algorithm} for d in datasets},
    }
    for d, algs in result["datasets"].items():
        for a, r in algs.items():
            print(d, a, json.dumps({k: r[k] for k in ("touched_best_f1", "false_negatives", "fp_binned")}))
    if args.out is not None:
        args.out.mkdir(parents=True, exist_ok=True)
        atomic_write_text(args.out / "touched_errors.json", json.dumps(result, indent=1))
        figure(result, args.out / "touched_errors.png")
        print(f"wrote {args.out / 'touched_errors.json'} and touched_errors.png")
    return result


if __name__ == "__main__":
    main()
