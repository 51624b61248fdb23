r"""Where the pooled errors of a Table 6.4 run lie: observed or never-observed cells, and the best F1 any map
can reach without predicting never-observed free space.

For each algorithm whose maps an experiment wrote (``[output] maps = true``), over all its datasets pooled
(every cell scored, as Table 6.4 and the experiment's own pooled scores do; a cell is called occupied when its
marginal is ``q_k > t``, ``t`` in the thresholds):

* the best F1, ``max_t 2 TP(t) / (2 TP(t) + FP(t) + FN(t))``, and its threshold;
* at that threshold, the false positives and false negatives among the *touched* cells (crossed or ended in
  by some ray; the datasets' ``touched`` masks) and among the never-touched ones.

And two oracle maps that know the truth of every touched cell exactly:

* ``touched truth, rest occupied``: every never-touched cell called occupied;
* ``touched truth, rest free``: every never-touched cell called free.

The better of the two bounds the pooled F1 of any map that gives every never-touched cell one value: to score
above it, a map must tell the free cells of never-observed space (rooms no ray entered) from the occupied ones.

:func:`error_split` computes it; :func:`error_split_text` is its printed summary.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from ogm_ppl.studies._inputs import maps_folders, npz_array
from ogm_ppl.studies.errors import StudyInputError

__all__ = ["ORACLES", "error_split", "error_split_text"]

#: the two oracle maps (module docstring)
ORACLES = ("touched truth, rest occupied", "touched truth, rest free")


def _counts(q: np.ndarray, truth: np.ndarray, thr: np.ndarray) -> np.ndarray:
    """``(3, len(thr))``: true positives, false positives, false negatives of ``q > t`` for each ``t``."""
    called = q[None, :] > thr[:, None]
    return np.stack([(called & truth).sum(1), (called & ~truth).sum(1), (~called & truth).sum(1)])


def _f1(tp, fp, fn) -> np.ndarray:
    tp, fp, fn = (np.asarray(x, dtype=np.float64) for x in (tp, fp, fn))
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(tp > 0, 2 * tp / (2 * tp + fp + fn), 0.0)


def error_split(
    out_dir: str | Path, thresholds: Sequence[float] | None = None, algorithms: Sequence[str] | None = None
) -> dict:
    """The error split of the experiment folder ``out_dir`` (module docstring): every algorithm with a map in
    the first dataset's folder (or those named in ``algorithms``), each of which must have a map in every
    dataset's folder; ``thresholds`` default to 0.01, 0.02, ..., 0.99.

    Returns ``{"datasets": n, "cells": {"touched", "untouched"}, "occupied": {"touched", "untouched"},
    "algorithms": {name: {"best_f1", "threshold", "precision", "recall", "fp_touched", "fn_touched",
    "fp_untouched", "fn_untouched"}}, "oracles": {name: best F1}}``.

    Raises:
        FileNotFoundError: no maps folder, no dataset folder, a dataset's truth or an algorithm's map missing.
        StudyInputError: a file without its array, or a map or mask of another size than the truth.
    """
    out_dir = Path(out_dir)
    folders = maps_folders(out_dir)
    thr = np.linspace(0.01, 0.99, 99) if thresholds is None else np.asarray(thresholds, dtype=np.float64)
    names = sorted(f.stem for f in folders[0].glob("*.npz")) if algorithms is None else list(algorithms)
    for d in folders:
        missing = [a for a in names if not (d / f"{a}.npz").is_file()]
        if missing:
            raise FileNotFoundError(f"{d}: no map of {', '.join(missing)} (pool only complete algorithms)")
    counts: dict[str, np.ndarray] = {}  # algorithm -> (2 masks [touched, untouched], 3, len(thr))
    oracle = np.zeros((2, 3), np.int64)
    cells = np.zeros(2, np.int64)
    occupied = np.zeros(2, np.int64)
    for d in folders:
        ev = out_dir / "datasets" / f"{d.name}.eval.npz"
        truth = npz_array(ev, "truth", "the dataset's truth").astype(bool)
        touched = npz_array(ev, "touched", "the dataset's touched cells").astype(bool)
        if touched.shape != truth.shape:
            raise StudyInputError(f"{ev}: touched has {touched.size} cells, truth {truth.size}")
        masks = (touched, ~touched)
        cells += [m.sum() for m in masks]
        occupied += [(truth & m).sum() for m in masks]
        t_in, t_out = truth[touched], truth[~touched]
        tp_in = t_in.sum()
        oracle[0] += [tp_in + t_out.sum(), (~t_out).sum(), 0]  # never-touched cells called occupied
        oracle[1] += [tp_in, 0, t_out.sum()]  # called free
        for f in (d / f"{a}.npz" for a in names):
            q = npz_array(f, "marginals", "a map").astype(np.float64)
            if q.shape != truth.shape:
                raise StudyInputError(f"{f}: {q.size} cells, the dataset's truth has {truth.size}")
            c = np.stack([_counts(q[m], truth[m], thr) for m in masks])
            counts[f.stem] = counts[f.stem] + c if f.stem in counts else c
    algs = {}
    for name, c in counts.items():
        tp, fp, fn = c.sum(0)
        f1 = _f1(tp, fp, fn)
        i = int(np.argmax(f1))
        algs[name] = {
            "best_f1": float(f1[i]),
            "threshold": float(thr[i]),
            "precision": float(tp[i] / max(tp[i] + fp[i], 1)),
            "recall": float(tp[i] / max(tp[i] + fn[i], 1)),
            "fp_touched": int(c[0, 1, i]),
            "fn_touched": int(c[0, 2, i]),
            "fp_untouched": int(c[1, 1, i]),
            "fn_untouched": int(c[1, 2, i]),
        }
    return {
        "datasets": len(folders),
        "cells": {"touched": int(cells[0]), "untouched": int(cells[1])},
        "occupied": {"touched": int(occupied[0]), "untouched": int(occupied[1])},
        "algorithms": algs,
        "oracles": {name: float(_f1(*oracle[j])) for j, name in enumerate(ORACLES)},
    }


def error_split_text(res: dict) -> str:
    """An :func:`error_split` result as lines of text: the never-touched cells, each algorithm's best F1 and
    its errors by where they lie, each oracle's best F1."""
    n_u, occ_u = res["cells"]["untouched"], res["occupied"]["untouched"]
    lines = [f"{res['datasets']} datasets; never-touched cells {n_u:,}, of them free {n_u - occ_u:,}"]
    for name, s in res["algorithms"].items():
        lines.append(
            f"{name:>24}: best F1 {s['best_f1']:.4f} at {s['threshold']:.2f}; FP touched {s['fp_touched']:,}, "
            f"never-touched {s['fp_untouched']:,}; FN touched {s['fn_touched']:,}, never-touched {s['fn_untouched']:,}"
        )
    for name, f1 in res["oracles"].items():
        lines.append(f"{name:>32}: best F1 {f1:.4f}")
    return "\n".join(lines)
