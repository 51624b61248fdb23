"""Fit the shipped pattern fields (``field:CORPUS`` one scale, ``field2:CORPUS`` two scales) per corpus.

    python experiments/fit_pattern_field.py                    # all corpora -> ogm_ppl/fitted/field_*.npz + .json
    python experiments/fit_pattern_field.py --corpus dungeon   # one corpus
    python experiments/fit_pattern_field.py --quick            # tiny corpora, writes under out/field_quick only

The training maps are those of the shipped tables (experiments/prior_stats.py --fit): ``generated`` = the 100
maps of 500 x 500 cells of ``ogm_ppl.datasets.mapgen.iter_corpus(100, (500, 500), seed=0)``; ``houseexpo``,
``ipa`` = their training plans (``training_plans``: the buildings of the real logs excluded), ``dungeon`` =
the first 300 training plans; rasterised by ``load_plan``'s defaults (outside = occupied, 20-cell margin).
Every tenth map (index 9, 19, ...) is the validation split that picks the stopping point; the rest train.
A 3 x 3 field (102 orbit parameters per scale) is fitted by pseudo-likelihood, then by persistent
contrastive divergence (``ogm_ppl.priors.learn_field``; settings in ``SETTINGS``), with an L2 penalty.
"""

from __future__ import annotations

import argparse
import hashlib
import io
import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from ogm_ppl.datasets import floorplans as fp  # noqa: E402
from ogm_ppl.datasets.mapgen import iter_corpus  # noqa: E402
from ogm_ppl.io import atomic_write_bytes, atomic_write_text  # noqa: E402
from ogm_ppl.priors.learn_field import data_crops, field_stats, fit_pcd, fit_pl  # noqa: E402
from ogm_ppl.priors.pattern_field import FIELD_FORMAT_VERSION, FITTED_DIR, load_field  # noqa: E402

CORPORA = ("generated", "houseexpo", "ipa", "dungeon")
SETTINGS = {
    "w": 3,
    "lambda_": 1e-3,
    "pl_max_iter": 200,
    "pcd_iterations": 300,
    "pcd_chains": 16,
    "pcd_size": 64,
    "pcd_sweeps_per_iteration": 1,
    "pcd_burn_in": 50,
    "pcd_lr": 0.05,
    "pcd_init": "crops of the training maps (data_crops, seed)",
    "eval_every": 20,
    "seed": 0,
    "validation": "maps with index % 10 == 9",
    "stopping": "smallest held-out frequency gap |f_val - f_model|_1 (iteration 0 = the PL solution)",
}


def corpus_maps(corpus: str, quick: bool):
    """``(list of (occupancy, known), provenance)`` of a corpus's training maps."""
    if corpus == "generated":
        n = 10 if quick else 100
        maps = [(m, np.ones_like(m)) for m in iter_corpus(n, (500, 500), seed=0)]
        names = [f"mapgen:{i}" for i in range(n)]
        prov = {"generator": "ogm_ppl.datasets.mapgen.iter_corpus", "n": n, "shape": [500, 500], "seed": 0}
    else:
        limit = 10 if quick else (300 if corpus == "dungeon" else None)
        names = fp.training_plans(corpus, limit=limit)
        maps = [(p.occupancy, p.known) for p in fp.iter_plans(corpus, names)]
        prov = {
            "split": "train",
            "plans": len(names),
            "excluded_buildings": list(fp.REAL_LOG_BUILDINGS),
            "resolution": fp.DEFAULT_RESOLUTION[corpus],
            "outside": "occupied",
            "margin": 20,
            "wall_cells": 2,
        }
    prov["corpus"] = corpus
    prov["plan_names_sha256"] = hashlib.sha256("\n".join(names).encode()).hexdigest()
    return maps, prov


def fit_corpus(corpus: str, out_dir: Path, quick: bool) -> dict:
    s = SETTINGS
    t0 = time.perf_counter()
    maps, prov = corpus_maps(corpus, quick)
    train = [m for i, m in enumerate(maps) if i % 10 != 9]
    val = [m for i, m in enumerate(maps) if i % 10 == 9]
    tr = field_stats(train, s["w"], 2)
    va = field_stats(val, s["w"], 2)
    t_stats = time.perf_counter() - t0
    print(f"{corpus}: {len(train)} training / {len(val)} validation maps, statistics in {t_stats:.1f} s", flush=True)
    init = data_crops(train, s["pcd_chains"], s["pcd_size"], s["seed"])
    fits = {}
    arrays: dict[str, np.ndarray] = {"w": np.array(s["w"], np.int64)}
    for scales in (1, 2):
        t1 = time.perf_counter()
        print(f" {corpus}, {scales} scale(s):", flush=True)
        th, th2, pll = fit_pl(tr, scales, s["lambda_"], s["pl_max_iter"])
        fit = fit_pcd(
            tr,
            va,
            th,
            th2,
            iterations=2 * s["eval_every"] if quick else s["pcd_iterations"],
            chains=s["pcd_chains"],
            size=s["pcd_size"],
            sweeps=s["pcd_sweeps_per_iteration"],
            burn_in=s["pcd_burn_in"],
            lr=s["pcd_lr"],
            lambda_=s["lambda_"],
            eval_every=s["eval_every"],
            seed=s["seed"],
            init=init,
        )
        fits[f"scales{scales}"] = {
            "train_pll_at_pl": pll,
            "best_iteration": fit.best_iteration,
            "best_heldout_gap": fit.best_gap,
            "validation_curve_columns": ["iteration", "heldout_gap", "validation_pll_per_cell", "seconds"],
            "validation_curve": [list(c) for c in fit.curve],
            "occupancy": fit.occupancy,
            "seconds": round(time.perf_counter() - t1, 2),
        }
        if scales == 1:
            arrays["theta"], arrays["occupancy"] = fit.theta, np.array(fit.occupancy)
        else:
            arrays["theta2_scale1"], arrays["theta2_scale2"] = fit.theta, fit.theta2
            arrays["occupancy2"] = np.array(fit.occupancy)
    lam = tr.win1 @ ((np.arange(len(tr.win1)) >> (s["w"] * s["w"] // 2)) & 1) / max(tr.win1.sum(), 1)
    buf = io.BytesIO()
    np.savez(buf, **arrays)
    path = atomic_write_bytes(out_dir / f"field_{corpus}.npz", buf.getvalue())
    load_field(path)  # what we ship must load
    info = {
        "file": path.name,
        "format_version": FIELD_FORMAT_VERSION,
        "sha256": hashlib.sha256(path.read_bytes()).hexdigest(),
        "bytes": path.stat().st_size,
        "seconds_incl_reading": round(time.perf_counter() - t0, 2),
        "statistics_seconds": round(t_stats, 2),
        "settings": s,
        "provenance": prov,
        "train_maps": len(train),
        "validation_maps": len(val),
        "train_cells_pl": int(tr.counts1.sum()),
        "validation_cells_pl": int(va.counts1.sum()),
        "window_centre_occupied_share": float(lam),
        "fits": fits,
    }
    atomic_write_text(out_dir / f"field_{corpus}.json", json.dumps(info, indent=1) + "\n")
    print(f"{corpus}: wrote {path} ({info['seconds_incl_reading']} s)", flush=True)
    return info


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--corpus", action="append", choices=CORPORA, help="fit only these (repeatable)")
    ap.add_argument("--quick", action="store_true", help="10 maps per corpus, 40 PCD iterations, out/field_quick")
    args = ap.parse_args(argv)
    out = ROOT / "out" / "field_quick" if args.quick else FITTED_DIR
    for corpus in args.corpus or CORPORA:
        fit_corpus(corpus, out, args.quick)


if __name__ == "__main__":
    main()
