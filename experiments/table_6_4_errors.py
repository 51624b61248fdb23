"""Where the pooled errors of a Table 6.4 run lie: observed or never-observed cells, and the best F1 any map
can reach without predicting never-observed free space.

For each algorithm whose maps an experiment wrote (``[output] maps = true``), over all its datasets pooled
(every cell scored, as Table 6.4 and the experiment's own pooled scores do; a cell is called occupied when
its marginal is ``> t``, ``t`` in the spec's thresholds):

* the best F1 and its threshold;
* at that threshold, the false positives and false negatives among the *touched* cells (crossed or ended in
  by some ray; the datasets' ``touched`` masks) and among the never-touched ones.

And two oracle maps that know the truth of every touched cell exactly:

* ``touched truth, rest occupied``: every never-touched cell called occupied;
* ``touched truth, rest free``: every never-touched cell called free.

The better of the two bounds the pooled F1 of any map that gives every never-touched cell one value: to
score above it, a map must tell the free cells of never-observed space (rooms no ray entered) from the
occupied ones.

    python experiments/table_6_4_errors.py out/experiments/table_6_4_full --json out/table_6_4_errors.json
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

ORACLES = ("touched truth, rest occupied", "touched truth, rest free")


def _array(path: Path, key: str, kind: str) -> np.ndarray:
    """The array ``key`` of the ``.npz`` file ``path`` (no pickles; errors name the path)."""
    if not path.is_file():
        raise FileNotFoundError(f"{path}: missing ({kind})")
    with np.load(path, allow_pickle=False) as z:
        if key not in z:
            raise ValueError(f"{path}: no {key!r} array (keys {sorted(z.keys())})")
        return np.asarray(z[key]).reshape(-1)


def _counts(q: np.ndarray, truth: np.ndarray, thr: np.ndarray) -> np.ndarray:
    """``(3, len(thr))``: true positives, false positives, false negatives of ``q > t`` for each ``t``."""
    called = q[None, :] > thr[:, None]
    return np.stack([(called & truth).sum(1), (called & ~truth).sum(1), (~called & truth).sum(1)])


def _f1(tp, fp, fn):
    tp, fp, fn = (np.asarray(x, dtype=np.float64) for x in (tp, fp, fn))
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(tp > 0, 2 * tp / (2 * tp + fp + fn), 0.0)


def error_split(out_dir: Path, thresholds=None, algorithms=None) -> dict:
    """``{"algorithms": {name: scores}, "oracles": {name: best F1}, "datasets": n, "cells": ...}`` for the
    experiment folder ``out_dir`` (module docstring): every algorithm with a map in the first dataset's folder
    (or those named in ``algorithms``), each of which must have a map in every dataset's folder."""
    out_dir = Path(out_dir)
    maps = out_dir / "maps"
    if not maps.is_dir():
        raise FileNotFoundError(f"{maps}: no maps folder (run the experiment with [output] maps = true)")
    thr = np.linspace(0.01, 0.99, 99) if thresholds is None else np.asarray(thresholds, dtype=np.float64)
    folders = sorted(p for p in maps.iterdir() if p.is_dir())
    if not folders:
        raise FileNotFoundError(f"{maps}: no dataset folders")
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
        truth = _array(ev, "truth", "the dataset's truth").astype(bool)
        touched = _array(ev, "touched", "the dataset's touched cells").astype(bool)
        if touched.shape != truth.shape:
            raise ValueError(f"{ev}: touched has {touched.size} cells, truth {truth.size}")
        masks = (touched, ~touched)
        cells += [m.sum() for m in masks]
        occupied += [(truth & m).sum() for m in masks]
        t_in, t_out = truth[touched], truth[~touched]
        tp_in = t_in.sum()
        oracle[0] += [tp_in + t_out.sum(), (~t_out).sum(), 0]  # never-touched cells called occupied
        oracle[1] += [tp_in, 0, t_out.sum()]  # called free
        for f in (d / f"{a}.npz" for a in names):
            q = _array(f, "marginals", "a map").astype(np.float64)
            if q.shape != truth.shape:
                raise ValueError(f"{f}: {q.size} cells, the dataset's truth has {truth.size}")
            c = np.stack([_counts(q[m], truth[m], thr) for m in masks])
            counts[f.stem] = counts.get(f.stem, 0) + c
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


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out_dir", type=Path, help="an experiment's output folder (holding maps/ and datasets/)")
    ap.add_argument("--algorithms", nargs="+", help="only these (default: every map of the first dataset)")
    ap.add_argument("--json", type=Path, help="also write the result to this JSON file")
    a = ap.parse_args(argv)
    res = error_split(a.out_dir, algorithms=a.algorithms)
    n_u, occ_u = res["cells"]["untouched"], res["occupied"]["untouched"]
    print(f"{res['datasets']} datasets; never-touched cells {n_u:,}, of them free {n_u - occ_u:,}")
    for name, s in res["algorithms"].items():
        print(
            f"{name:>24}: best F1 {s['best_f1']:.4f} at {s['threshold']:.2f}; FP touched {s['fp_touched']:,}, "
            f"never-touched {s['fp_untouched']:,}; FN touched {s['fn_touched']:,}, never-touched {s['fn_untouched']:,}"
        )
    for name, f1 in res["oracles"].items():
        print(f"{name:>32}: best F1 {f1:.4f}")
    if a.json:
        from ogm_ppl.io import atomic_write_text

        print("wrote", atomic_write_text(a.json, json.dumps(res, indent=1)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
