"""Fit the shipped pattern fields (``field:CORPUS`` one scale, ``field2:CORPUS`` two scales) per corpus.

    python experiments/fit_pattern_field.py                    # all corpora -> ogm_ppl/fitted/field_*.npz + .json
    python experiments/fit_pattern_field.py --corpus dungeon   # one corpus
    python experiments/fit_pattern_field.py --quick            # tiny corpora, writes under out/field_quick only
    python experiments/fit_pattern_field.py --check-only       # rerun the sampler check of the shipped fits

The training maps are those of the shipped tables (experiments/prior_stats.py --fit): ``generated`` = the 100
maps of 500 x 500 cells of ``ogm_ppl.datasets.mapgen.iter_corpus(100, (500, 500), seed=0)``; ``houseexpo``,
``ipa`` = their training plans (``training_plans``: the buildings of the real logs excluded), ``dungeon`` =
the first 300 training plans; rasterised by ``load_plan``'s defaults (outside = occupied, 20-cell margin).
Every tenth map (index 9, 19, ...) is the validation split that picks the stopping point; the rest train.
A 3 x 3 field (102 orbit parameters per scale) is fitted by pseudo-likelihood with an L2 penalty centred on
the potentials of a 2 x 2 field fitted the same way (``backoff_potentials``: patterns the plans never showed are
scored by the smaller field, not by 0), then tempered: the power ``beta`` of the field whose prior samples,
from the all-free and from the all-occupied map alike, come closest to the validation maps' window frequencies,
with a unary bias giving them the training windows' occupied share (``fit_tempered``;
``ogm_ppl.priors.learn_field``; settings in ``SETTINGS``). The untempered PL field is in an
ordered phase (the sampler keeps each start's phase); the chosen ``beta`` lies just below its transition.
"""

from __future__ import annotations

import argparse
import hashlib
import io
import json
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from ogm_ppl.datasets import floorplans as fp  # noqa: E402
from ogm_ppl.datasets.mapgen import iter_corpus  # noqa: E402
from ogm_ppl.io import atomic_write_bytes, atomic_write_text  # noqa: E402
from ogm_ppl.priors.learn_field import (  # noqa: E402
    backoff_potentials,
    field_stats,
    fit_pl,
    fit_tempered,
    sampler_check,
)
from ogm_ppl.priors.pattern_field import FIELD_FORMAT_VERSION, FITTED_DIR, load_field  # noqa: E402

CORPORA = ("generated", "houseexpo", "ipa", "dungeon")
SETTINGS: dict[str, Any] = {
    "w": 3,
    "backoff_w": 2,
    "backoff_lambda_": 1e-3,
    "lambda_": 1e-2,
    "pl_max_iter": 200,
    "penalty": "lambda_/2 |theta - theta0|^2, theta0 = backoff_potentials(2 x 2 PL field); scale 2 centred at 0",
    "betas": [round(float(b), 3) for b in np.arange(0.3, 0.8001, 0.05)],
    "bias": "unary bias matched to the training windows' centre-cell occupied share (bisection)",
    "bias_steps": 5,
    "bias_range": 1.5,
    "agree": 0.1,
    "check_size": 64,
    "check_chains": 4,
    "check_sweeps": 300,
    "seed": 0,
    "validation": "maps with index % 10 == 9",
    "stopping": "largest beta whose chains from all-free and all-occupied agree on occupancy within `agree`, "
    "their mean within `agree` of the target (smallest mean held-out gap |f_val - f_model|_1 among those)",
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
    tr_small = field_stats(train, s["backoff_w"], 1)
    t_stats = time.perf_counter() - t0
    print(f"{corpus}: {len(train)} training / {len(val)} validation maps, statistics in {t_stats:.1f} s", flush=True)
    phi, _, pll_small = fit_pl(tr_small, 1, s["backoff_lambda_"], s["pl_max_iter"])
    theta0 = backoff_potentials(phi, s["backoff_w"], s["w"])
    fits: dict = {"backoff": {"w": s["backoff_w"], "phi": phi.tolist(), "train_pll": pll_small}}
    arrays: dict[str, np.ndarray] = {"w": np.array(s["w"], np.int64)}
    betas = s["betas"][::3] if quick else s["betas"]
    lam = tr.win1 @ ((np.arange(len(tr.win1)) >> (s["w"] * s["w"] // 2)) & 1) / max(tr.win1.sum(), 1)
    for scales in (1, 2):
        t1 = time.perf_counter()
        print(f" {corpus}, {scales} scale(s):", flush=True)
        th, th2, pll = fit_pl(tr, scales, s["lambda_"], s["pl_max_iter"], theta0=theta0)
        fit = fit_tempered(
            va,
            th,
            th2,
            betas=betas,
            occupancy=float(lam),
            bias_steps=s["bias_steps"],
            bias_range=s["bias_range"],
            size=s["check_size"],
            chains=s["check_chains"],
            sweeps=s["check_sweeps"],
            agree=s["agree"],
            seed=s["seed"],
        )
        fits[f"scales{scales}"] = {
            "train_pll_at_pl": pll,
            "beta": fit.beta,
            "best_heldout_gap": fit.best_gap,
            "search_columns": [
                "beta",
                "heldout_gap_mean_of_starts",
                "occupancy_from_free",
                "occupancy_from_occupied",
                "bias",
            ],
            "search": [list(c) for c in fit.curve],
            "occupancy": fit.occupancy,
            "seconds": round(time.perf_counter() - t1, 2),
        }
        if scales == 1:
            arrays["theta"], arrays["occupancy"] = fit.theta, np.array(fit.occupancy)
        else:
            arrays["theta2_scale1"], arrays["theta2_scale2"] = fit.theta, np.asarray(fit.theta2)
            arrays["occupancy2"] = np.array(fit.occupancy)
    buf = io.BytesIO()
    np.savez(buf, **arrays)  # type: ignore[arg-type]
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
        "sampler_check": sampler_report(arrays, va),
    }
    atomic_write_text(out_dir / f"field_{corpus}.json", json.dumps(info, indent=1) + "\n")
    print(f"{corpus}: wrote {path} ({info['seconds_incl_reading']} s)", flush=True)
    return info


def sampler_report(arrays: dict, va) -> dict:
    """What the compiled sampler draws from the fitted fields: :func:`sampler_check` on 64 x 64 and 128 x 128
    grids from the all-free, all-occupied and noise maps (4 chains, 300 sweeps, the last 100 read), with
    the held-out gap to the validation maps, and the validation maps' window-centre occupied share."""
    w = int(arrays["w"])
    lam = va.win1 @ ((np.arange(len(va.win1)) >> (w * w // 2)) & 1) / max(va.win1.sum(), 1)
    out: dict = {"validation_window_centre_occupied_share": float(lam)}
    for key, t1, t2 in (
        ("scales1", arrays["theta"], None),
        ("scales2", arrays["theta2_scale1"], arrays["theta2_scale2"]),
    ):
        rows = sampler_check(t1, t2, w, va, sizes=(64, 128), starts=("free", "occupied", "noise"), sweeps=300, seed=0)
        out[key] = rows
        print(
            f"  sampler check {key}: "
            + ", ".join(f"{r['size']} {r['start']} occ {r['occupancy']:.3f} gap {r['gap']:.3f}" for r in rows),
            flush=True,
        )
    return out


def check_only(corpus: str, out_dir: Path) -> None:
    """Recompute ``sampler_check`` of an existing fit in ``out_dir`` and store it in its JSON."""
    path = out_dir / f"field_{corpus}.json"
    info = json.loads(path.read_text())
    d = load_field(out_dir / f"field_{corpus}.npz")
    maps, _ = corpus_maps(corpus, False)
    va = field_stats([m for i, m in enumerate(maps) if i % 10 == 9], d["w"], 2)
    print(f"{corpus}:", flush=True)
    info["sampler_check"] = sampler_report(d, va)
    atomic_write_text(path, json.dumps(info, indent=1) + "\n")


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--corpus", action="append", choices=CORPORA, help="fit only these (repeatable)")
    ap.add_argument("--quick", action="store_true", help="10 maps per corpus, 5 powers beta, out/field_quick")
    ap.add_argument("--out", default=None, help="output folder (default ogm_ppl/fitted, or out/field_quick)")
    ap.add_argument("--check-only", action="store_true", help="only rerun the sampler check of existing fits")
    args = ap.parse_args(argv)
    out = Path(args.out) if args.out else (ROOT / "out" / "field_quick" if args.quick else FITTED_DIR)
    for corpus in args.corpus or CORPORA:
        if args.check_only:
            check_only(corpus, out)
        else:
            fit_corpus(corpus, out, args.quick)


if __name__ == "__main__":
    main()
