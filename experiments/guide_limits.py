r"""What limits a corpus guide's prediction of unseen cells: its calibration, or what it can tell apart?

On the held-out maps of a test corpus, under the calibration protocol (:mod:`ogm_ppl.calibration`: the same windows,
stop-and-scan data and unseen near-mapped cells), for each guide ``g`` (``--guides``, names as
``ogm-ppl calibrate --guides`` takes them) this reports, in bits per unseen cell (mean over maps):

* ``nll``: the guide as shipped;
* ``nll_oracle_temperature``: the guide's logits divided by the one temperature ``T`` (on a grid of 0.5 .. 4)
  that minimises the mean NLL *on these test maps*, and ``nll_oracle_affine`` with a shift ``b`` too
  (``l / T + b``). Fitted on the test maps themselves, these are lower bounds on what any recalibration of the
  guide's marginals (temperature scaling, Platt scaling; Guo et al. 2017) could reach; they leave the ranking
  of the cells, so AUC and best F1, unchanged. A guide whose NLL they barely lower is limited by what it tells
  apart, not by how it states its confidence;
* ``nll_ensemble``: the mean of the guides' probabilities (a mixture: one more way to buy NLL without a
  larger network);
* per map: the map's name, its unseen cells and their occupied share, and every guide's NLL, so that the
  buildings behind the mean are visible (several windows of a test corpus can be variants of one building).

    python experiments/guide_limits.py --test ipa --guides ipa houseexpo+ipa@sym   # ~2 min on 2 cores
    python experiments/guide_limits.py --test houseexpo --guides houseexpo houseexpo+ipa@sym --guide-dir DIR
    python experiments/guide_limits.py --test ipa --guides ipa ipa=out/capacity/c12 ipa=out/capacity/c48

Writes ``--out`` (default ``out/guide_limits``)/``guide_limits.json`` (settings, provenance, per-map rows, summary).
The leakage checks of :mod:`ogm_ppl.calibration` apply: a guide is never scored on a plan (or building) it was
trained on.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from ogm_ppl import GaussianRange, OccupancyModel
from ogm_ppl import calibration as C  # the protocol, windows, guides and leakage checks
from ogm_ppl.io import atomic_write_text, writable_folder
from ogm_ppl.metrics import nll_bits
from ogm_ppl.priors import IndependentPrior

TEMPERATURES = np.round(np.arange(0.5, 4.0001, 0.05), 3)
SHIFTS = np.round(np.arange(-1.5, 1.5001, 0.125), 3)
EPS = 1e-6  # the clip of ogm_ppl.metrics.nll_bits: logits of clipped probabilities stay finite


def recalibrated(logits: list[np.ndarray], ys: list[np.ndarray], shifts=(0.0,)) -> tuple[float, float, float]:
    """``(mean NLL over maps, T, b)`` of ``sigmoid(l / T + b)`` at the best ``T`` in :data:`TEMPERATURES` and
    ``b`` in ``shifts``, chosen on these maps."""
    best = (np.inf, 1.0, 0.0)
    for T in TEMPERATURES:
        for b in shifts:
            v = float(np.mean([nll_bits(1 / (1 + np.exp(-(lg / T + b))), y) for lg, y in zip(logits, ys)]))
            if v < best[0]:
                best = (v, float(T), float(b))
    return best


def main(argv=None) -> dict:
    from benchmarks._common import provenance

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--test", required=True, choices=C.TEST_CORPORA, help="the test corpus")
    ap.add_argument(
        "--guides",
        nargs="+",
        required=True,
        help="guide names, as ogm-ppl calibrate --guides takes; NAME=DIR reads that guide from DIR (e.g. one trained "
        "with other --channels), so several trainings of one guide can be compared",
    )
    ap.add_argument("--guide-dir", type=Path, default=None, help="read the guides as DIR/guide_CORPUS.npz")
    ap.add_argument("--plans", type=int, default=10, help="held-out maps of the test corpus (default 10)")
    ap.add_argument("--out", type=Path, default=Path("out/guide_limits"))
    args = ap.parse_args(argv)
    torch.set_num_threads(1)
    try:
        writable_folder(args.out)
    except OSError as e:
        raise SystemExit(f"guide_limits.py: --out {e}") from None
    if args.plans < 1:
        raise SystemExit("guide_limits.py: --plans must be at least 1")
    proto = C.CalibrationSettings(plans=args.plans)  # the calibration protocol, at its defaults
    maps = C.heldout_maps(args.test, args.plans, proto.window, proto.generated_shape)
    guides = {}
    for entry in args.guides:  # NAME, or NAME=DIR: the guide NAME read from DIR (another training of it)
        name, _, folder = entry.partition("=")
        guides[entry] = C.guide_for(name, Path(folder) if folder else args.guide_dir)
        for c in C.guide_corpora(name):
            C.check_heldout(args.test, [t.plan for t in maps], c)
    t0 = time.perf_counter()
    rows, logits, ys = [], {g: [] for g in guides}, []
    for t in maps:
        scene = C.make_scene(t, proto)
        model = OccupancyModel(
            scene.grid, scene.rays, GaussianRange(proto.sigma), IndependentPrior(0.5, scene.grid.num_cells)
        )
        unseen = scene.masks["unseen"]
        y = t.truth.ravel()[unseen].astype(np.float64)
        ys.append(y)
        row: dict = {"plan": t.name, "unseen_cells": int(unseen.sum()), "occupied_share": float(y.mean())}
        probs = []
        for g, guide in guides.items():
            q = np.clip(guide.marginals(model).numpy()[unseen], EPS, 1 - EPS)
            logits[g].append(np.log(q / (1 - q)))
            probs.append(q)
            row[g] = nll_bits(q, y)
        row["ensemble"] = nll_bits(np.mean(probs, axis=0), y)
        rows.append(row)
        print(f"  {t.name[:40]:<40} " + " ".join(f"{k} {v:.3f}" for k, v in row.items() if k in guides), flush=True)
    summary = {}
    for g in guides:
        t_only = recalibrated(logits[g], ys)
        affine = recalibrated(logits[g], ys, SHIFTS)
        summary[g] = {
            "nll": float(np.mean([r[g] for r in rows])),
            "nll_oracle_temperature": t_only[0],
            "oracle_temperature": t_only[1],
            "nll_oracle_affine": affine[0],
            "oracle_affine": [affine[1], affine[2]],
        }
    summary["ensemble"] = {"nll": float(np.mean([r["ensemble"] for r in rows])), "of": list(guides)}
    doc = {
        "provenance": provenance(),
        "settings": {
            "test": args.test,
            "guides": args.guides,
            "guide_dir": None if args.guide_dir is None else str(args.guide_dir),
            "plans": args.plans,
            "protocol": {k: getattr(proto, k) for k in ("window", "poses", "beams", "range_cells", "sigma", "seed")},
            "temperatures": [float(TEMPERATURES[0]), float(TEMPERATURES[-1])],
            "shifts": [float(SHIFTS[0]), float(SHIFTS[-1])],
        },
        "rows": rows,
        "summary": summary,
        "seconds": time.perf_counter() - t0,
    }
    path = atomic_write_text(args.out / "guide_limits.json", json.dumps(doc, indent=1))
    for g, s in summary.items():
        print(f"{g}: " + ", ".join(f"{k} {v:.3f}" if isinstance(v, float) else f"{k} {v}" for k, v in s.items()))
    print(f"wrote {path}")
    return doc


if __name__ == "__main__":
    main()
