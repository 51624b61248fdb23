r"""Where a method's bits go on the unseen cells: NLL by distance to the nearest cell some ray reached.

The protocol of ``ogm-ppl calibrate`` (the same held-out maps, windows, stop-and-scan data and unseen
cells ``U``: near-mapped cells no ray reached), and one method: an amortised guide (``--guide``, a name
``ogm-ppl calibrate --guides`` takes, e.g. ``houseexpo+ipa@sym``) or a prior sampled by chains (``--prior``, a
prior name; a name without ``:CORPUS`` is learned on each test corpus's own training plans, as
``ogm-ppl calibrate --diagonal`` runs it), with the calibration run's leakage checks. Each unseen cell ``k`` is
binned by its Euclidean distance ``d_k`` (in cells) to the nearest reached cell; per test corpus and bin: the
share of the unseen cells in it, their occupied share and the method's NLL in bits per cell,
``-1/|B| sum_{k in B} log2 q_k^{m_k} (1 - q_k)^{1 - m_k}`` (``q`` clipped as
:func:`~ogm_ppl.metrics.nll_bits` clips it). The bins' NLLs weighted by their shares give the
pooled NLL over the corpus's unseen cells (``ogm-ppl calibrate`` reports the mean over maps instead).

A prior runs the calibration protocol's three chains (``--kernel``, ``--sweeps``, ``--burn`` as
``ogm-ppl calibrate`` takes them; ``q`` their pooled marginals), and each bin also gets the share of its cells
whose chains agree (split R-hat below 1.05) and each chain's mean occupancy there. ``--sweeps`` takes several
values: one run per value, from the same seeds, so agreement can be followed as the chains grow longer.

    python experiments/unseen_by_distance.py --guide houseexpo+ipa@sym --test houseexpo ipa   # about a minute
    python experiments/unseen_by_distance.py --prior border_bo@cal --kernel cycle --test dungeon --plans 2 \
        --sweeps 200 1000 3000
    python experiments/unseen_by_distance.py --plan-files out/log_plans --plan-set logs --plan-outside unknown

``--plan-files`` (and ``--plan-set``, ``--pixel-size``, ``--plan-outside``, as ``ogm-ppl calibrate`` takes them) bins
plans of other buildings too; a prior run on them must name its corpus (``KIND:CORPUS``).

Writes ``OUT/unseen_by_distance.json`` (settings, provenance, one row per corpus, bin and sweep count) and
prints a table.
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

import ogm_ppl.calibration as calibration  # the protocol, windows and guides
from ogm_ppl import GaussianRange, OccupancyModel
from ogm_ppl.cli.calibrate import add_plan_file_arguments, check_plan_file_arguments
from ogm_ppl.datasets.plan_files import PlanFileError
from ogm_ppl.io import atomic_write_text
from ogm_ppl.metrics import nll_bits
from ogm_ppl.priors import IndependentPrior

#: bin edges of the distance to the nearest reached cell, in cells: (0, 1.5] holds the 8 neighbours
EDGES = (0.0, 1.5, 3.0, 6.0, float("inf"))
TESTS = ("generated", "houseexpo", "ipa", "dungeon")


def _bins(d: np.ndarray, unseen: np.ndarray) -> list[np.ndarray]:
    return [unseen & (d > EDGES[i]) & (d <= EDGES[i + 1]) for i in range(len(EDGES) - 1)]


def _maps(test: str, args: argparse.Namespace, train_corpora: list[str]):
    if args.plan_files and test == args.plan_set:
        try:
            maps = calibration.plan_set_maps(args, args.plan_limit)
        except (PlanFileError, calibration.LeakageError, calibration.NoUsablePlanError) as e:
            raise SystemExit(f"unseen_by_distance.py: {e}") from None
    else:
        maps = calibration.heldout_maps(test, args.plans, args.window)
    for corpus in train_corpora:  # never a map of the method's training plans
        calibration.check_heldout(test, [t.plan for t in maps], corpus)
    return maps


def _distance(scene) -> np.ndarray:
    return distance_transform_edt(~scene.rays.reached().reshape(scene.grid.shape))


def _bits(q: np.ndarray, truth: np.ndarray, m: np.ndarray) -> float:
    """The summed NLL in bits of the cells ``m``, under :func:`~ogm_ppl.metrics.nll_bits`'s clipping."""
    return nll_bits(q, truth, m) * int(m.sum()) if m.any() else 0.0


def _add(acc: dict, bins: list[np.ndarray], q: np.ndarray, truth: np.ndarray) -> None:
    """Add one map's bins to the sums ``acc["n"]``, ``acc["bits"]`` and ``acc["occ"]`` (cells, NLL bits,
    occupied cells per bin) under the marginals ``q``."""
    for i, m in enumerate(bins):
        acc["n"][i] += m.sum()
        acc["bits"][i] += _bits(q, truth, m)
        acc["occ"][i] += truth[m].sum()


def _sums(nb: int) -> dict:
    return {"n": np.zeros(nb), "bits": np.zeros(nb), "occ": np.zeros(nb)}


def _rows(test: str, maps: int, n, bits, occ, extra: dict | None = None) -> list[dict]:
    total = max(n.sum(), 1)
    rows = []
    for i in range(len(EDGES) - 1):
        row = {
            "test": test,
            "maps": maps,
            "distance": [EDGES[i], EDGES[i + 1] if np.isfinite(EDGES[i + 1]) else None],  # None: no upper edge
            "cells": int(n[i]),
            "share": float(n[i] / total),
            "occupied_share": float(occ[i] / max(n[i], 1)),
            "nll_bits": float(bits[i] / max(n[i], 1)),
        }
        for key, v in (extra or {}).items():
            row[key] = v[i]
        rows.append(row)
    return rows


def by_distance(test: str, guide, args: argparse.Namespace) -> list[dict]:
    """The rows of one test corpus under a guide: per distance bin, the unseen cells' share, occupied share and
    NLL."""
    acc = _sums(len(EDGES) - 1)
    maps = _maps(test, args, calibration.guide_corpora(args.guide))
    for t in maps:
        scene = calibration.make_scene(t, args)
        model = OccupancyModel(
            scene.grid, scene.rays, GaussianRange(args.sigma), IndependentPrior(0.5, scene.grid.num_cells)
        )
        q = guide.marginals(model).numpy().reshape(t.truth.shape)
        _add(acc, _bins(_distance(scene), scene.masks["unseen"].reshape(t.truth.shape)), q, t.truth.astype(bool))
    return _rows(test, len(maps), acc["n"], acc["bits"], acc["occ"])


def chains_by_distance(test: str, args: argparse.Namespace) -> list[dict]:
    """The rows of one test corpus under a prior's chains, one set per ``args.sweeps`` value: per distance bin
    the guide rows' fields, plus ``agree`` (share of the bin's cells whose split R-hat is below 1.05) and
    ``chain_occupied`` (each chain's mean marginal over the bin's cells, in :data:`calibration.STARTS` order)."""
    name, train = calibration.prior_names([args.prior], [test])[-1]  # KIND:TEST[@MOD] unless it names a corpus
    if test not in TESTS and train == test:
        raise SystemExit(f"{args.prior}: no prior is learned on the plan set {test!r}; name one as KIND:CORPUS")
    maps = _maps(test, args, [train])
    nb, C = len(EDGES) - 1, len(calibration.STARTS)
    acc = {S: {**_sums(nb), "ok": np.zeros(nb), "chain": np.zeros((nb, C))} for S in args.sweeps}
    for t in maps:
        scene = calibration.make_scene(t, args)
        truth = t.truth.astype(bool)
        unseen_2d = scene.masks["unseen"].reshape(t.truth.shape)
        bins = _bins(_distance(scene), unseen_2d)
        idx = np.flatnonzero(unseen_2d.ravel())  # the order of run["rhat"]
        for S in args.sweeps:
            burn = S // 4 if args.burn is None else args.burn
            run = calibration.run_chains(scene, name, argparse.Namespace(**{**vars(args), "sweeps": S, "burn": burn}))
            if "skipped" in run:
                raise SystemExit(f"{name} on {t.name}: {run['skipped']}")
            marg = run["marginals"].reshape(C, *t.truth.shape)
            agree = np.zeros(t.truth.shape, bool)
            agree.ravel()[idx] = calibration.agreeing(run["rhat"])
            a = acc[S]
            _add(a, bins, np.clip(marg.mean(0), 0.0, 1.0), truth)
            for i, m in enumerate(bins):
                a["ok"][i] += agree[m].sum()
                a["chain"][i] += marg[:, m].sum(1)
            print(f"  {t.name} {name} {S} sweeps: agree {agree.ravel()[idx].mean():.3f}", flush=True)
    rows = []
    for S, a in acc.items():
        n = np.maximum(a["n"], 1)
        extra = {
            "agree": [float(a["ok"][i] / n[i]) for i in range(nb)],
            "chain_occupied": [[float(v / n[i]) for v in a["chain"][i]] for i in range(nb)],
        }
        for r in _rows(test, len(maps), a["n"], a["bits"], a["occ"], extra):
            rows.append({"prior": name, "sweeps": S, **r})
    return rows


def _print(rows: list[dict], what: str) -> None:
    chains = "agree" in rows[0]
    print(f"{what}, unseen cells by distance to the nearest reached cell (cells)")
    head = f"{'test':10s} {'distance':>10s} {'share':>6s} {'occupied':>9s} {'NLL bits':>9s}"
    print(
        head + (f" {'sweeps':>7s} {'agree':>6s}  chain occupancy ({', '.join(calibration.STARTS)})" if chains else "")
    )
    for r in rows:
        lo, hi = r["distance"]
        span = f"({lo:g}, {'inf' if hi is None else f'{hi:g}'}]"
        line = f"{r['test']:10s} {span:>10s} {r['share']:6.2f} {r['occupied_share']:9.2f} {r['nll_bits']:9.3f}"
        if chains:
            line += f" {r['sweeps']:7d} {r['agree']:6.2f}  " + " ".join(f"{v:.2f}" for v in r["chain_occupied"])
        print(line)


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    what = ap.add_mutually_exclusive_group()
    what.add_argument(
        "--guide", default=None, help="a guide name ogm-ppl calibrate --guides takes (default houseexpo+ipa@sym)"
    )
    what.add_argument("--prior", default=None, help="a prior name (KIND[:CORPUS][@MOD]), sampled by chains")
    ap.add_argument("--guide-dir", type=Path, default=None, help="read the guide as DIR/guide_C.npz")
    ap.add_argument("--kernel", default="cycle", choices=sorted(calibration.KERNELS), help="a prior's sampler")
    ap.add_argument("--sweeps", type=int, nargs="+", default=[200], help="kept sweeps per chain (one run each)")
    ap.add_argument("--burn", type=int, default=None, help="warm-up sweeps per chain (default: a quarter of --sweeps)")
    ap.add_argument(
        "--test", nargs="+", default=None, choices=TESTS, help="test corpora (default: all, or none with --plan-files)"
    )
    add_plan_file_arguments(ap)
    ap.add_argument(
        "--plans", type=int, default=None, help="held-out maps per test corpus (default 10; every plan of --plan-files)"
    )
    ap.add_argument("--out", type=Path, default=Path("out/unseen_by_distance"))
    args = ap.parse_args(argv)
    args.plan_limit = args.plans  # None: every plan of --plan-files
    args.plans = 10 if args.plans is None else args.plans
    if args.plans < 1:
        raise SystemExit("--plans must be at least 1")
    if min(args.sweeps) < 4 or (args.burn is not None and args.burn < 0):
        raise SystemExit("--sweeps must be at least 4 (split R-hat halves each chain) and --burn at least 0")
    if args.prior is None and args.guide is None:
        args.guide = "houseexpo+ipa@sym"
    check_plan_file_arguments(ap, args)
    if args.test is None:
        args.test = [] if args.plan_files else list(TESTS)
    tests = args.test + ([args.plan_set] if args.plan_files else [])
    proto = calibration.CalibrationSettings(plans=args.plans)  # the calibration protocol's sensor and window
    for k in ("window", "poses", "beams", "range_cells", "sigma", "seed", "max_support"):
        setattr(args, k, getattr(proto, k))
    args.sweeps = list(dict.fromkeys(args.sweeps))  # one run per distinct length
    from benchmarks._common import provenance

    t0 = time.perf_counter()
    if args.prior is not None:
        rows = [r for test in tests for r in chains_by_distance(test, args)]
        _print(rows, f"{args.prior} ({args.kernel}, 3 chains)")
        settings = {"prior": args.prior, "kernel": args.kernel, "sweeps": args.sweeps, "burn": args.burn}
    else:
        guide = calibration.guide_for(args.guide, args.guide_dir)
        rows = [r for test in tests for r in by_distance(test, guide, args)]
        _print(rows, f"guide:{args.guide}")
        settings = {"guide": args.guide, "guide_dir": None if args.guide_dir is None else str(args.guide_dir)}
    doc = {
        "provenance": provenance(),
        "settings": {
            **settings,
            "plans": args.plans,
            "window": args.window,
            "edges": [e if np.isfinite(e) else None for e in EDGES],
            **(
                {
                    "plan_files": [str(p) for p in args.plan_files],
                    "plan_set": args.plan_set,
                    "pixel_size": args.pixel_size,
                    "plan_outside": args.plan_outside,
                }
                if args.plan_files
                else {}
            ),
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
