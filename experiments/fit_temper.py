r"""Fit each learned prior's tempering exponent on validation plans: the ``@cal`` of :mod:`ogm_ppl.priors.named`.

A prior learned by counting (the MRF's ``psi``, the tile tables, their backed-off forms; Chapter 5) is fitted to
whole maps, not to what it must do in mapping: predict the cells no ray reached. Tables whose configurations are
near-deterministic given their border freeze the sampler into confident guesses, and a confident mistake costs
many bits. Raising the prior to a power ``beta <= 1`` (:class:`~ogm_ppl.priors.TemperedPrior`,
``p~(m)^beta``) weakens its coupling; ``beta`` is chosen here, on training data only, by the quantity the
calibration benchmark scores.

The protocol, per corpus. The training plans are split as :mod:`experiments.fit_backoff` splits them (natural
order, every fifth plan is *validation*; the backed-off kinds use the shipped Witten-Bell ``kappa``, which was
chosen on exactly this split). Every table is counted on the *fit* part only (8 symmetries,
``min_count_5x5 = 2``). The first ``--plans`` validation plans with at least 200 free cells in their window are
cropped and simulated exactly as ``experiments/calibration.py`` does (its ``choose_window``, ``make_scene`` and
``run_prior``: ``C = 3`` chains from the thresholded OGM, the all-free map and a prior draw, their marginals
pooled). For ``generated`` (no plan names) the validation maps are fresh draws of the generator from a seed
stream no table and no held-out map uses (:data:`VALIDATION_SEED`), and the shipped tables are used. For each
kind and each ``beta`` of ``--betas`` the score is the NLL in bits per cell on the unseen cells ``U`` (near-mapped
cells no ray reached), averaged over the plans; ``beta`` with the lowest mean wins (ties: the larger ``beta``).

Output ``ogm_ppl/fitted/temper_<corpus>.json`` (``--out`` folder): ``beta`` per kind, every ``(beta, kind)``
score per plan, the settings and provenance (plan-name hashes, git commit, seconds), read by
:func:`ogm_ppl.priors.named.load_temper_params`.

    python experiments/fit_temper.py --corpus houseexpo            # one corpus
    python experiments/fit_temper.py --quick --out out/fit_temper  # smoke run (2 small plans, 2 betas, 2 kinds)
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
import torch  # noqa: E402
from select_headline_prior import split_names  # noqa: E402

from ogm_ppl.calibration import generated_windows, make_scene, run_prior, usable_windows  # noqa: E402
from ogm_ppl.datasets import floorplans as fp  # noqa: E402
from ogm_ppl.io import atomic_write_text  # noqa: E402
from ogm_ppl.priors.learn import count_tables  # noqa: E402
from ogm_ppl.priors.named import TEMPER_FORMAT  # noqa: E402

CORPORA = ("generated", "houseexpo", "ipa", "dungeon")
#: the kinds built from counted tables (the fields fit their own exponent on their own split)
KINDS = ("mrf", "mrf8", "patch3", "border", "border1", "patch3_bo", "border_bo", "border1_bo")
BETAS = (1.0, 0.75, 0.5, 0.35, 0.25, 0.15, 0.1, 0.05)
#: validation generated map ``i`` is ``generate_map(KINDS[i % 4], seed=VALIDATION_SEED + i)``: a root seed
#: stream apart from the tables' spawned children and from the held-out maps' (calibration, 50_000 + i)
VALIDATION_SEED = 70_000
OUT_DEFAULT = ROOT / "ogm_ppl" / "fitted"


def validation_maps(corpus: str, names: list[str], args) -> list:
    """The first ``args.plans`` usable validation maps (calibration's ``TestMap``), cropped to ``args.window``."""
    if corpus == "generated":
        return generated_windows(args.plans, args.generated_shape, args.window, VALIDATION_SEED)
    out = usable_windows(corpus, names, args.plans, args.window)
    if len(out) < args.plans:
        raise SystemExit(f"{corpus}: only {len(out)} of the {args.plans} validation plans have a usable window")
    return out


def choose(scores: dict[float, list[float]]) -> float:
    """The ``beta`` with the lowest mean NLL (ties: the larger ``beta``)."""
    return min(scores, key=lambda b: (float(np.mean(scores[b])), -b))


def parse_args(argv=None) -> argparse.Namespace:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--corpus", nargs="+", default=list(CORPORA), choices=CORPORA)
    ap.add_argument("--kinds", nargs="+", default=list(KINDS))
    ap.add_argument("--betas", nargs="+", type=float, default=list(BETAS))
    ap.add_argument("--plans", type=int, default=3, help="validation plans per corpus")
    ap.add_argument("--window", type=int, default=96)
    ap.add_argument("--generated-shape", type=int, default=160)
    ap.add_argument("--poses", type=int, default=3)
    ap.add_argument("--beams", type=int, default=90)
    ap.add_argument("--range-cells", type=float, default=75.0)
    ap.add_argument("--sigma", type=float, default=1.0)
    ap.add_argument("--sweeps", type=int, default=100, help="kept sweeps per chain")
    ap.add_argument("--burn", type=int, default=25)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--max-support", type=int, default=4096)
    ap.add_argument("--kernel", default="gibbs")
    ap.add_argument("--out", type=Path, default=None, help=f"folder (default {OUT_DEFAULT.relative_to(ROOT)})")
    ap.add_argument("--quick", action="store_true")
    ap.add_argument(
        "--update", action="store_true", help="keep the other kinds of an existing file; refit only --kinds"
    )
    args = ap.parse_args(argv)
    if any(not (0.0 <= b <= 1.0) for b in args.betas):
        raise SystemExit(f"--betas must lie in [0, 1], got {args.betas}")
    if args.quick:
        args.plans, args.window, args.sweeps, args.burn = 2, 48, 10, 4
        args.betas, args.kinds = args.betas[:2], args.kinds[:2]
        args.corpus = args.corpus[:1] if len(args.corpus) < len(CORPORA) else ["dungeon"]
        args.out = args.out or ROOT / "out" / "fit_temper"
    args.out = args.out or OUT_DEFAULT
    return args


def fit_corpus(corpus: str, args) -> dict:
    t0 = time.perf_counter()
    prov: dict = {"excluded_buildings": list(fp.REAL_LOG_BUILDINGS)}
    if corpus == "generated":
        tables, counted = None, 0.0
        maps = validation_maps(corpus, [], args)
        prov.update(tables="shipped (ogm_ppl/fitted/prior_generated.npz)", validation_seed=VALIDATION_SEED)
    else:
        fit, val = split_names(corpus)
        if args.quick:
            fit = fit[:10]
        tables = count_tables(fp.iter_plans(corpus, fit), symmetries=True, min_count_5x5=2, progress=False)
        counted = time.perf_counter() - t0
        maps = validation_maps(corpus, val, args)
        prov.update(
            tables="counted on the fit part",
            fit_plans=len(fit),
            fit_names_sha256=hashlib.sha256("\n".join(fit).encode()).hexdigest(),
            validation_names_sha256=hashlib.sha256("\n".join(val).encode()).hexdigest(),
        )
    scenes = [make_scene(t, args) for t in maps]
    validation: dict[str, dict] = {}
    beta: dict[str, float] = {}
    for kind in args.kinds:
        per: dict[float, list[float]] = {}
        rhat: dict[float, list[float]] = {}
        skipped = None
        for b in args.betas:
            name = f"{kind}:{corpus}" + ("" if b == 1.0 else f"@{b:g}")
            for sc in scenes:
                r = run_prior(sc, name, args, tables=tables)
                if "skipped" in r:
                    skipped = r["skipped"]
                    break
                per.setdefault(b, []).append(float(r["scores"]["unseen"]["nll_bits"]))
                rhat.setdefault(b, []).append(float(r["rhat_below"]))
            if skipped:
                break
            print(
                f"  {corpus:>9} {kind:>10} beta {b:<5g} NLL {np.mean(per[b]):.3f} "
                f"(R-hat<1.05 {np.mean(rhat[b]):.2f}; {time.perf_counter() - t0:.0f} s)",
                flush=True,
            )
        if skipped:
            print(f"  {corpus:>9} {kind:>10} skipped: {skipped}", flush=True)
            continue
        beta[kind] = choose(per)
        validation[kind] = {
            "betas": list(per),
            "nll_bits": [per[b] for b in per],
            "mean_nll_bits": [float(np.mean(per[b])) for b in per],
            "rhat_below": [float(np.mean(rhat[b])) for b in per],
        }
        print(f"  {corpus:>9} {kind:>10} -> beta {beta[kind]:g}", flush=True)
    try:
        rev = subprocess.run(["git", "rev-parse", "HEAD"], cwd=ROOT, capture_output=True, text=True).stdout.strip()
    except OSError:
        rev = ""
    prov.update(
        validation_plans_scored=[t.name for t in maps],
        fitted_by="experiments/fit_temper.py",
        git=rev,
        counting_seconds=round(counted, 1),
        seconds=round(time.perf_counter() - t0, 1),
    )
    settings = {k: (str(v) if isinstance(v, Path) else v) for k, v in vars(args).items() if k not in ("out", "corpus")}
    return {
        "format": TEMPER_FORMAT,
        "format_version": 1,
        "corpus": corpus,
        "beta": beta,
        "criterion": "mean NLL (bits per cell) of the unseen near-mapped cells over the validation plans; "
        "3 chains from different starts pooled (calibration.run_prior); ties -> the larger beta",
        "validation": validation,
        "settings": settings,
        "provenance": prov,
    }


def _merge(old: dict, new: dict, path: Path) -> dict:
    """``old`` with ``new``'s kinds replaced; refused unless both were fitted with the same protocol (the
    settings other than the kinds and the exponent grid)."""
    skip = ("kinds", "betas", "update")
    a = {k: v for k, v in old.get("settings", {}).items() if k not in skip}
    b = {k: v for k, v in new["settings"].items() if k not in skip}
    if a != b or old.get("corpus") != new["corpus"]:
        raise SystemExit(f"--update: {path} was fitted with other settings; refit every kind instead")
    out = dict(old)
    out["beta"] = {**old["beta"], **new["beta"]}
    out["validation"] = {**old["validation"], **new["validation"]}
    out["provenance"] = {**old["provenance"], "updated": new["provenance"]}
    return out


def main(argv=None) -> list[dict]:
    args = parse_args(argv)
    torch.set_num_threads(1)
    docs = []
    for corpus in args.corpus:
        doc = fit_corpus(corpus, args)
        args.out.mkdir(parents=True, exist_ok=True)
        path = args.out / f"temper_{corpus}.json"
        if args.update and path.is_file():
            doc = _merge(json.loads(path.read_text()), doc, path)
        atomic_write_text(path, json.dumps(doc, indent=1))
        print(f"{corpus}: {doc['beta']} -> {path}", flush=True)
        docs.append(doc)
    return docs


if __name__ == "__main__":
    main()
