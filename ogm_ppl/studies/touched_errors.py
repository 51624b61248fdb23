r"""Where maps' errors on the touched cells of an experiment lie, against the benchmark's walls (results page,
Intel: "Where the touched cells differ").

For an experiment folder written by ``ogm-ppl experiment`` on a log (the truth ``T`` is the benchmark map:
traditional OGM from all readings; ``U`` the touched cells, crossed or ended in by some ray), each dataset and
algorithm is read at the algorithm's best touched-only threshold ``t`` (``maps/D/A.json``), a cell called
occupied when its marginal is ``q_k > t``. Two chessboard distance transforms place the errors:

* the *depth* of a touched occupied cell into its wall, ``d(k, U \ T)`` (cells from the nearest touched
  free cell: 1, 2, 3 and more); per depth, the share of those cells called occupied;
* the *distance* of a touched false positive from the walls, ``d(k, T)`` (1: the cell in front of a wall face;
  2-3; 4 and more: free space).

Walls missed are the touched occupied cells not called occupied. The counts must give back the touched best F1
``2 TP / (2 TP + FN + FP)`` the experiment recorded, else the cells, the truth or the threshold are not the
experiment's and the study refuses them.

:func:`touched_errors` runs the study over datasets and algorithms (and writes ``touched_errors.json`` and
``touched_errors.png`` into a folder given); :func:`count_touched_errors` counts one pair.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from ogm_ppl.studies.errors import StudyInputError

__all__ = ["FP_BINS", "count_touched_errors", "touched_errors", "touched_errors_figure"]

#: the bins of the false positives' distance to the nearest benchmark wall (cells)
FP_BINS = ("1", "2-3", "4+")


def count_touched_errors(folder: str | Path, dataset: str, algorithm: str) -> dict:
    """The counts of the module docstring for one dataset and algorithm of the experiment in ``folder``:
    ``{"threshold", "touched_best_f1", "walls_by_depth": {depth: {"cells", "called_occupied"}},
    "false_positives", "fp_by_distance_1_to_6plus", "fp_binned", "true_positives", "false_negatives"}``.

    Raises:
        StudyInputError: the counts do not give the touched best F1 the experiment recorded (the same cells,
            truth and threshold).
    """
    from scipy import ndimage

    folder = Path(folder)
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
        raise StudyInputError(
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


def touched_errors(
    folder: str | Path,
    algorithms: Sequence[str],
    *,
    datasets: Sequence[str] | None = None,
    out_dir: str | Path | None = None,
) -> dict:
    """:func:`count_touched_errors` of each of ``datasets`` (default: every scored dataset of ``folder``) and
    ``algorithms``: ``{"experiment": str(folder), "algorithms": [...], "datasets": {dataset: {algorithm:
    counts}}}``. With ``out_dir``, also writes ``touched_errors.json`` (the dict) and ``touched_errors.png``
    (:func:`touched_errors_figure`) there.

    Raises:
        StudyInputError: ``folder`` is no experiment folder, has no scored dataset, lacks a map named, or its
            counts disagree with its scores.
    """
    folder = Path(folder)
    if not (folder / "datasets").is_dir():
        raise StudyInputError(f"{folder}: not an experiment folder (no datasets/)")
    scored = sorted(p.name[: -len(".eval.npz")] for p in (folder / "datasets").glob("*.eval.npz"))
    names = list(datasets) if datasets else scored
    if not names:
        raise StudyInputError(f"{folder}: no scored dataset (datasets/*.eval.npz)")
    for d in names:
        for a in algorithms:
            if not (folder / "maps" / d / f"{a}.npz").is_file():
                raise StudyInputError(f"{folder}: no map of algorithm {a!r} on dataset {d!r}")
    result = {
        "experiment": str(folder),
        "algorithms": list(algorithms),
        "datasets": {d: {a: count_touched_errors(folder, d, a) for a in algorithms} for d in names},
    }
    if out_dir is not None:
        from ogm_ppl.io import atomic_write_text

        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        atomic_write_text(out / "touched_errors.json", json.dumps(result, indent=1))
        touched_errors_figure(result, out / "touched_errors.png")
    return result


def touched_errors_figure(result: dict, path: str | Path) -> Path:
    """One panel per dataset of a :func:`touched_errors` result: per algorithm a bar of walls missed and one of
    false positives, stacked by distance to the nearest benchmark wall; written to ``path`` (PNG)."""
    from ogm_ppl.io import atomic_write
    from ogm_ppl.viz import _plt

    plt = _plt()
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
    return Path(path)
