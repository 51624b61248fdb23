r"""Where a guide's bits go on the unseen cells: NLL by distance to the nearest cell some ray reached.

The protocol of ``experiments/calibration.py`` (the same held-out maps, windows, stop-and-scan data and unseen
cells ``U``: near-mapped cells no ray reached), one amortised guide (``--guide``, a name ``calibration.py
--guides`` takes, e.g. ``houseexpo+ipa@sym``; the leakage check is the calibration script's). Each unseen cell
``k`` is binned by its Euclidean distance ``d_k`` (in cells) to the nearest reached cell; per test corpus and bin:
the share of the unseen cells in it, their occupied share and the guide's NLL in bits per cell,
``-1/|B| sum_{k in B} log2 q_k^{m_k} (1 - q_k)^{1 - m_k}``. The bins' NLLs weighted by their shares give the
pooled NLL over the corpus's unseen cells (``calibration.py`` reports the mean over maps instead).

    python experiments/unseen_by_distance.py --guide houseexpo+ipa@sym --test houseexpo ipa   # about a minute

Writes ``OUT/unseen_by_distance.json`` (settings, provenance, one row per corpus and bin) and prints a table.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
from scipy.ndimage import distance_transform_edt

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

import calibration  # experiments/calibration.py: the protocol, windows and guides

from ogm_ppl import GaussianRange, OccupancyModel
from ogm_ppl.io import atomic_write_text
from ogm_ppl.priors import IndependentPrior

#: bin edges of the distance to the nearest reached cell, in cells: (0, 1.5] holds the 8 neighbours
EDGES = (0.0, 1.5, 3.0, 6.0, float("inf"))
TESTS = ("generated", "houseexpo", "ipa", "dungeon")


def by_distance(test: str, guide, args: argparse.Namespace) -> list[dict]:
    """The rows of one test corpus: per distance bin, the unseen cells' share, occupied share and NLL."""
    n = np.zeros(len(EDGES) - 1)
    bits = np.zeros(len(EDGES) - 1)
    occ = np.zeros(len(EDGES) - 1)
    maps = calibration.heldout_maps(test, args.plans, args.window)
    for corpus in calibration.guide_corpora(args.guide):  # never a map of the guide's training plans
        calibration.check_heldout(test, [t.plan for t in maps], corpus)
    for t in maps:
        scene = calibration.make_scene(t, args)
        model = OccupancyModel(
            scene.grid, scene.rays, GaussianRange(args.sigma), IndependentPrior(0.5, scene.grid.num_cells)
        )
        q = np.clip(guide.marginals(model).numpy().reshape(t.truth.shape), 1e-12, 1 - 1e-12)
        truth = t.truth.astype(bool)
        unseen = scene.masks["unseen"].reshape(t.truth.shape)
        d = distance_transform_edt(~scene.rays.reached().reshape(t.truth.shape))
        nll = -np.where(truth, np.log2(q), np.log2(1 - q))
        for i in range(len(EDGES) - 1):
            m = unseen & (d > EDGES[i]) & (d <= EDGES[i + 1])
            n[i] += m.sum()
            bits[i] += nll[m].sum()
            occ[i] += truth[m].sum()
    total = max(n.sum(), 1)
    return [
        {
            "test": test,
            "maps": len(maps),
            "distance": [EDGES[i], EDGES[i + 1] if np.isfinite(EDGES[i + 1]) else None],  # None: no upper edge
            "cells": int(n[i]),
            "share": float(n[i] / total),
            "occupied_share": float(occ[i] / max(n[i], 1)),
            "nll_bits": float(bits[i] / max(n[i], 1)),
        }
        for i in range(len(EDGES) - 1)
    ]


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--guide", default="houseexpo+ipa@sym", help="a guide name calibration.py --guides takes")
    ap.add_argument("--guide-dir", type=Path, default=None, help="read the guide as DIR/guide_C.npz")
    ap.add_argument("--test", nargs="+", default=list(TESTS), choices=TESTS)
    ap.add_argument("--plans", type=int, default=10, help="held-out maps per test corpus (default 10)")
    ap.add_argument("--out", type=Path, default=Path("out/unseen_by_distance"))
    args = ap.parse_args(argv)
    if args.plans < 1:
        raise SystemExit("--plans must be at least 1")
    proto = calibration.parse_args(["--plans", str(args.plans)])  # the calibration protocol's sensor and window
    for k in ("window", "poses", "beams", "range_cells", "sigma", "seed"):
        setattr(args, k, getattr(proto, k))
    from benchmarks._common import provenance

    t0 = time.perf_counter()
    guide = calibration.guide_for(args.guide, args.guide_dir)
    rows = [r for test in args.test for r in by_distance(test, guide, args)]
    print(f"guide:{args.guide}, unseen cells by distance to the nearest reached cell (cells)")
    print(f"{'test':10s} {'distance':>10s} {'share':>6s} {'occupied':>9s} {'NLL bits':>9s}")
    for r in rows:
        lo, hi = r["distance"]
        span = f"({lo:g}, {'inf' if hi is None else f'{hi:g}'}]"
        print(f"{r['test']:10s} {span:>10s} {r['share']:6.2f} {r['occupied_share']:9.2f} {r['nll_bits']:9.3f}")
    doc = {
        "provenance": provenance(),
        "settings": {
            "guide": args.guide,
            "guide_dir": None if args.guide_dir is None else str(args.guide_dir),
            "plans": args.plans,
            "window": args.window,
            "edges": [e if np.isfinite(e) else None for e in EDGES],
        },
        "rows": rows,
        "seconds": time.perf_counter() - t0,
    }
    args.out.mkdir(parents=True, exist_ok=True)
    path = args.out / "unseen_by_distance.json"
    atomic_write_text(path, json.dumps(doc, indent=1, allow_nan=False))
    print(f"wrote {path} ({doc['seconds']:.0f} s)")
    return doc


if __name__ == "__main__":
    main()
