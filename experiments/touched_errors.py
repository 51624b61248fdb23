"""Where a map's errors on the touched cells of an experiment lie, against the benchmark's walls.

For an experiment folder written by ``ogm-ppl experiment`` (a log dataset: the truth is the benchmark map),
one dataset and one algorithm: at the algorithm's best touched-only threshold (``maps/D/A.json``), the share
of the touched benchmark-occupied cells called occupied, by depth into the wall (chessboard cells from the
nearest touched benchmark-free cell), and the false positives on touched cells by their distance to the
nearest benchmark-occupied cell. README, Intel section: "Why touched-only F1 stays below traditional OGM's".

    python experiments/touched_errors.py out/experiments/intel_6_5 intel-pf1 dd-L1
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
from scipy import ndimage


def touched_errors(folder: Path, dataset: str, algorithm: str) -> dict:
    ev = np.load(folder / "datasets" / f"{dataset}.eval.npz")
    truth, touched = ev["truth"].astype(bool), ev["touched"].astype(bool)
    q = np.load(folder / "maps" / dataset / f"{algorithm}.npz")["marginals"]
    thr = json.loads((folder / "maps" / dataset / f"{algorithm}.json").read_text())["touched"]["threshold"]
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
    return {
        "threshold": thr,
        "walls_by_depth": by_depth,
        "false_positives": int(fp.sum()),
        "fp_by_distance_1_to_6plus": np.bincount(np.minimum(dist[fp], 6), minlength=7)[1:].tolist(),
        "true_positives": int((pred & occ).sum()),
        "false_negatives": int((~pred & occ).sum()),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("folder", type=Path)
    ap.add_argument("dataset")
    ap.add_argument("algorithm", nargs="+")
    args = ap.parse_args()
    for a in args.algorithm:
        print(a, json.dumps(touched_errors(args.folder, args.dataset, a)))


if __name__ == "__main__":
    main()
