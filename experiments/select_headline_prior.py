r"""Choose the prior of the headline experiment (``make run``) on training plans, never on the Intel log.

    python experiments/select_headline_prior.py            # -> ogm_ppl/fitted/headline_prior.json
    python experiments/select_headline_prior.py --quick    # tiny: 2 plans, 2 candidates, under out/ only

The protocol. The training plans of the corpus (``training_plans`` without the real-log buildings, in their
natural order) are split as :mod:`experiments.fit_backoff` splits them: every fifth plan (``index % 5 == 4``)
is *validation*, the rest *fit*. Every table is counted on the fit part only (8 symmetries, the shipped
``min_count_5x5 = 2``); the backed-off kinds use the shipped Witten-Bell ``kappa``, which
``fit_backoff.py`` chose on exactly this split. On ``--plans`` validation plans, each cropped to the
``--window`` window holding the most wall-side cells (``calibration.choose_window``), a sparse stop-and-scan
dataset is simulated (``--poses`` stops of a frontier route, ``--beams`` beams, range ``--range-cells``, range
noise ``--sigma`` cells: the setting of the headline's Gibbs sensor model) and every candidate maps it as the
headline does: patch Gibbs with ``L = 9`` (3 x 3 patches, Algorithm 2) from the thresholded OGM start,
``--sweeps`` sweeps after ``--burn`` burn-in. Scores on the near-mapped mask (cells within 10 cells of a
reached cell, Fig. 6.16b): best F1 and ROC AUC; the candidate with the highest mean best F1 over the plans
wins (AUC breaks ties), and traditional OGM (Hähnel) is scored beside them as a reference.

The output ``ogm_ppl/fitted/headline_prior.json`` names the winner (``prior`` kind, ``corpus``, kernel
``update``) with every candidate's scores, the settings and the provenance (hashes of the fit and validation
plan names, git commit, seconds); :func:`ogm_ppl.experiment.headline.headline_prior` reads and validates it.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "experiments"))

import numpy as np  # noqa: E402

from ogm_ppl import GaussianRange, OccupancyModel  # noqa: E402
from ogm_ppl.calibration import make_scene, usable_windows  # noqa: E402
from ogm_ppl.datasets import floorplans as fp  # noqa: E402
from ogm_ppl.experiment.headline import HEADLINE_PRIOR_FORMAT  # noqa: E402
from ogm_ppl.inference import PatchGibbs, RunningStats, evidence_grid, run_gibbs  # noqa: E402
from ogm_ppl.io import atomic_write_text  # noqa: E402
from ogm_ppl.metrics import prediction_scores  # noqa: E402
from ogm_ppl.models import delta_by_name  # noqa: E402
from ogm_ppl.priors.learn import count_tables  # noqa: E402
from ogm_ppl.priors.named import prior_by_name  # noqa: E402

#: ``(kind, update)`` pairs; ``update`` is PatchGibbs's (``"gibbs"``: the exact conditional)
CANDIDATES = (
    ("patch3", "gibbs"),
    ("patch3_bo", "gibbs"),
    ("border", "gibbs"),
    ("border", "thesis"),
    ("border_bo", "gibbs"),
    ("mrf", "gibbs"),
)
OUT_DEFAULT = ROOT / "ogm_ppl" / "fitted" / "headline_prior.json"


def split_names(corpus: str) -> tuple[list[str], list[str]]:
    """``(fit, validation)`` plan names of ``corpus``: every fifth training plan is validation."""
    limit = 300 if corpus == "dungeon" else None
    names = fp.training_plans(corpus, limit=limit)
    return [n for i, n in enumerate(names) if i % 5 != 4], [n for i, n in enumerate(names) if i % 5 == 4]


def validation_scenes(corpus: str, names: list[str], args) -> list[dict]:
    """The first ``args.plans`` validation plans with at least 200 free cells in their window, each with its
    simulated sparse dataset, rays and near-mapped mask (the calibration experiment's scene)."""
    scenes: list[dict] = []
    for t in usable_windows(corpus, names, args.plans, args.window):
        sc = make_scene(t, args)
        near = sc.masks["near"].reshape(sc.grid.shape)
        scenes.append({"plan": t.plan, "truth": t.truth, "grid": sc.grid, "rays": sc.rays, "near": near})
    if len(scenes) < args.plans:
        raise SystemExit(f"only {len(scenes)} of the {args.plans} validation plans asked for have a usable window")
    return scenes


def score(q: np.ndarray, scene: dict) -> dict:
    s = prediction_scores(q, scene["truth"].ravel(), mask=scene["near"].ravel())
    return {"best_f1": float(s["best_f1"]), "auc": float(s["auc"]), "nll_bits": float(s["nll_bits"])}


def run_candidate(kind: str, update: str, corpus: str, tables, scene: dict, args) -> dict:
    prior = prior_by_name(f"{kind}:{corpus}", scene["grid"].shape, tables=tables)
    model = OccupancyModel(scene["grid"], scene["rays"], GaussianRange(args.sigma), prior)
    t0 = time.perf_counter()
    kernel = PatchGibbs(model, (3, 3), update=update)
    stats = RunningStats(model)
    run_gibbs(kernel, args.sweeps, stats, warmup=args.burn, seed=args.seed, progress=False)
    out = score(np.clip(stats.marginals.numpy(), 0.0, 1.0), scene)
    out["seconds"] = time.perf_counter() - t0
    return out


def parse_args(argv=None) -> argparse.Namespace:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--corpus", default="houseexpo", choices=("houseexpo", "ipa", "dungeon"))
    ap.add_argument("--plans", type=int, default=8)
    ap.add_argument("--window", type=int, default=128)
    ap.add_argument("--poses", type=int, default=4)
    ap.add_argument("--beams", type=int, default=180)
    ap.add_argument("--range-cells", type=float, default=75.0)
    ap.add_argument("--sigma", type=float, default=0.5)
    ap.add_argument("--sweeps", type=int, default=60)
    ap.add_argument("--burn", type=int, default=10)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", type=Path, default=None, help=f"default {OUT_DEFAULT.relative_to(ROOT)}")
    ap.add_argument("--quick", action="store_true")
    args = ap.parse_args(argv)
    if args.quick:
        args.plans, args.window, args.sweeps, args.burn = 2, 64, 6, 2
        args.out = args.out or ROOT / "out" / "select_headline_prior" / "headline_prior.json"
    args.out = args.out or OUT_DEFAULT
    return args


def main(argv=None) -> dict:
    args = parse_args(argv)
    t0 = time.perf_counter()
    fit, val = split_names(args.corpus)
    if args.quick:
        fit = fit[:10]
    tables = count_tables(fp.iter_plans(args.corpus, fit), symmetries=True, min_count_5x5=2, progress=False)
    counted = time.perf_counter() - t0
    scenes = validation_scenes(args.corpus, val, args)
    candidates = CANDIDATES[:2] if args.quick else CANDIDATES
    rows = []
    for s in scenes:
        ogm = evidence_grid(s["rays"], delta_by_name("haehnel"))
        rows.append({"plan": s["plan"], "candidate": "ogm", **score(ogm.probabilities.numpy(), s)})
        for kind, update in candidates:
            r = run_candidate(kind, update, args.corpus, tables, s, args)
            rows.append({"plan": s["plan"], "candidate": f"{kind}/{update}", **r})
            f1, auc, sec = r["best_f1"], r["auc"], r["seconds"]
            print(f"{s['plan']:>24}  {kind:>10} {update:>6}  F1 {f1:.3f}  AUC {auc:.3f}  {sec:.1f} s")
    means = {}
    for name in ["ogm"] + [f"{k}/{u}" for k, u in candidates]:
        rs = [r for r in rows if r["candidate"] == name]
        means[name] = {key: float(np.mean([r[key] for r in rs])) for key in ("best_f1", "auc", "nll_bits")}
    best = max((f"{k}/{u}" for k, u in candidates), key=lambda n: (means[n]["best_f1"], means[n]["auc"]))
    kind, update = best.split("/")
    try:
        rev = subprocess.run(["git", "rev-parse", "HEAD"], cwd=ROOT, capture_output=True, text=True).stdout.strip()
    except OSError:
        rev = ""
    doc = {
        "format": HEADLINE_PRIOR_FORMAT,
        "format_version": 1,
        "prior": kind,
        "corpus": args.corpus,
        "update": update,
        "criterion": "mean best F1 on the near-mapped mask of the validation plans (AUC breaks ties)",
        "means": means,
        "rows": rows,
        "settings": {k: (str(v) if isinstance(v, Path) else v) for k, v in vars(args).items()},
        "provenance": {
            "fit_names_sha256": hashlib.sha256("\n".join(fit).encode()).hexdigest(),
            "validation_names_sha256": hashlib.sha256("\n".join(val).encode()).hexdigest(),
            "fit_plans": len(fit),
            "validation_plans_scored": [s["plan"] for s in scenes],
            "excluded_buildings": list(fp.REAL_LOG_BUILDINGS),
            "selected_by": "experiments/select_headline_prior.py",
            "command": " ".join(["python", "experiments/select_headline_prior.py", *(argv or sys.argv[1:])]),
            "git": rev,
            "counting_seconds": round(counted, 1),
            "seconds": round(time.perf_counter() - t0, 1),
        },
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_text(args.out, json.dumps(doc, indent=1))
    print("\nmean over plans (near-mapped mask):")
    for name, m in means.items():
        print(f"  {name:>18}  F1 {m['best_f1']:.3f}  AUC {m['auc']:.3f}  NLL {m['nll_bits']:.3f}")
    print(f"chosen: {kind}:{args.corpus} (update {update}) -> {args.out}")
    return doc


if __name__ == "__main__":
    main()
