"""The net field next to the pattern field: time per sweep on the same grid and held-out conditional NLL.

Timing (every ratio measured in the same run, interleaved rounds, best CPU time of each):

* prior-only single-cell sweeps of a ``--size`` square grid (a crop of a houseexpo validation plan), through the
  generic compiled sweep every kernel uses (``prior_gibbs_sweeps``, a bundle per chain: the net field's
  conditionals kept by neighbourhood content, :mod:`ogm_ppl.priors.compiled.net_memo`) for ``field:houseexpo`` and
  the net field;
* a posterior single-cell Gibbs sweep and a 3 x 3 patch Gibbs sweep (``CellGibbs``, ``PatchGibbs``; one round of
  the patch sweeps, the net field's take seconds) of a simulated ``--scene`` square scene under each prior (the
  independent prior's sweep as the baseline).

Score: the mean ``-log p(m_k | m_-k)`` over the cells of the houseexpo validation plans (every 10th training plan,
as the fits split them) whose ``(2w - 1)^2`` neighbourhood is known, by each prior's compiled conditionals, for
``field:houseexpo`` (the shipped, tempered field), the net field and, with ``--field-pl``, the pattern field's
pseudo-likelihood stage before tempering (fitted here on the training plans, about a minute).

    python benchmarks/bench_net_field.py [--net out/fitted/net_houseexpo.npz] [--field-pl] [--size 128]

Without ``--net`` the net field is a seeded random one of the default architecture (timing only). Writes
out/bench/bench_net_field.json.
"""

from __future__ import annotations

import os

os.environ.setdefault("NUMBA_NUM_THREADS", "1")

import argparse
import sys
import time

import numpy as np
import torch

sys.path.insert(0, os.path.dirname(__file__))
from _common import sparse_scene, write_json

from ogm_ppl import GaussianRange, OccupancyModel, raycast
from ogm_ppl.inference.mcmc.gibbs import CellGibbs, PatchGibbs
from ogm_ppl.learn import NetFieldSettings
from ogm_ppl.learn._fit_common import load_training_plans, validation_split
from ogm_ppl.priors import IndependentPrior, NetFieldPrior, prior_by_name
from ogm_ppl.priors.compiled import prior_gibbs_sweeps
from ogm_ppl.priors.learn_net import heldout_nll
from ogm_ppl.priors.net_field import net_from_file

torch.set_default_dtype(torch.float64)


def random_net(shape) -> NetFieldPrior:
    s = NetFieldSettings()
    rng = np.random.default_rng(0)
    f = rng.normal(0, 1 / s.w, (s.hidden, s.w, s.w))
    b, v = rng.normal(0, 0.1, s.hidden), rng.normal(0, 0.3, s.hidden)
    return NetFieldPrior(shape, f, b, v, -0.3, s.pad, s.activation)


def interleaved(fns: dict, rounds: int) -> dict[str, float]:
    """Best CPU time of each function over ``rounds`` rounds that run every function in turn (one untimed call
    first in each round). CPU time of the process (one numba thread), not wall time: on a shared machine a call of a
    few milliseconds is preempted more often than a shorter one, which skews wall-time ratios."""
    best = dict.fromkeys(fns, float("inf"))
    for _ in range(rounds):
        for name, fn in fns.items():
            fn()
            t0 = time.process_time()
            fn()
            best[name] = min(best[name], time.process_time() - t0)
    return best


def prior_sweeps(field, net, start: np.ndarray, rounds: int) -> dict:
    """Seconds per prior-only single-cell sweep of 4 chains from ``start``, each chain with a bundle of its own (the
    net field's bundle keeps its conditionals by neighbourhood content, as one kernel's chain does)."""
    n = int(np.sqrt(start.size))
    maps = {k: np.ascontiguousarray(np.repeat(start[None], 4, 0)) for k in ("field", "net")}
    bundles = {"field": [field.compiled()] * 4, "net": [net.with_shape((n, n)).compiled() for _ in range(4)]}

    def sweep(kind):
        for i, b in enumerate(bundles[kind]):
            prior_gibbs_sweeps(b, maps[kind][i : i + 1], 1, i)

    fns = {"field": lambda: sweep("field"), "net": lambda: sweep("net")}
    t = {k: v / 4 for k, v in interleaved(fns, rounds).items()}
    out = {f"{k}_seconds": v for k, v in t.items()}
    out["net_vs_field"] = t["net"] / t["field"]
    print(f"prior-only single-cell sweep, {n}^2 cells (per chain):")
    for k, v in t.items():
        print(f"  {k:13s} {v * 1e3:9.2f} ms  ({v / start.size * 1e9:8.1f} ns a cell) = {v / t['field']:7.1f}x field")
    return out


def posterior_sweeps(net, n: int, rounds: int) -> dict:
    """Seconds per CellGibbs and 3 x 3 PatchGibbs sweep of a simulated ``n x n`` scene under each prior."""
    grid, scans = sparse_scene(n, max(4, n // 5), walls=max(4, n * n // 6000), seed=0, beams=360)
    rays = raycast(grid, scans)
    models = {
        "independent": OccupancyModel(grid, rays, GaussianRange(3.0), IndependentPrior(0.234, grid.num_cells)),
        "field": OccupancyModel(grid, rays, GaussianRange(3.0), prior_by_name("field:houseexpo", grid.shape)),
        "net": OccupancyModel(grid, rays, GaussianRange(3.0), net.with_shape(grid.shape)),
    }
    out: dict = {"cells": grid.num_cells, "rays": rays.num_rays}
    for label, make, r in (("cell", CellGibbs, rounds), ("patch3", lambda m: PatchGibbs(m, patch=(3, 3)), 1)):
        torch.manual_seed(0)
        kernels = {k: make(m) for k, m in models.items()}
        state = {}
        for k, kern in kernels.items():
            kern.setup()
            state[k] = kern.sample(kern.current_params())

        def step(k, kernels=kernels, state=state):
            state[k] = kernels[k].sample(state[k])

        t = interleaved({k: (lambda k=k: step(k)) for k in kernels}, r)
        print(f"posterior {label} sweep, {n}^2 cells, {rays.num_rays:,} rays:")
        for k, v in t.items():
            out[f"{label}_{k}_seconds"] = v
            rel = f"{v / t['independent']:7.1f}x independent, {v / t['field']:7.1f}x field"
            print(f"  {k:12s} {v * 1e3:9.1f} ms = {rel}")
        out[f"{label}_net_vs_field"] = t["net"] / t["field"]
    return out


def scores(net, w: int, field_pl: bool) -> dict:
    """Held-out ``-log p(m_k | m_-k)`` per cell on the houseexpo validation plans (module docstring)."""
    plans = load_training_plans("houseexpo")
    tr_idx, va_idx = validation_split(len(plans), 10)
    val = [(p.occupancy, p.known) for p in plans.maps(va_idx)]
    priors = {"field:houseexpo": lambda s: prior_by_name("field:houseexpo", s).compiled()}
    priors["net"] = lambda s: net.with_shape(s).compiled()
    if field_pl:
        from ogm_ppl.priors import PatternFieldPrior
        from ogm_ppl.priors.learn_field import backoff_potentials, field_stats, fit_pl

        train = [(p.occupancy, p.known) for p in plans.maps(tr_idx)]
        phi, _, _ = fit_pl(field_stats(train, 2, 1), 1, 1e-3, 200, progress=False)
        th, _, _ = fit_pl(field_stats(train, 3, 1), 1, 1e-2, 200, theta0=backoff_potentials(phi, 2, 3), progress=False)
        priors["field PL stage (beta = 1)"] = lambda s: PatternFieldPrior(s, th, 3).compiled()
    out = {}
    print(f"held-out -log p(m_k | m_-k), houseexpo validation plans, cells with a known {2 * w - 1}^2 neighbourhood:")
    for k, make in priors.items():
        t0 = time.perf_counter()
        nll, cells = heldout_nll(make, val, w)
        out[k] = {"nll": nll, "cells": cells, "seconds": time.perf_counter() - t0}
        print(f"  {k:28s} {nll:.5f} nats/cell over {cells:,} cells ({out[k]['seconds']:.1f} s)")
    return out


def main() -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--net", default=None, help="a net field file (default: a random one, timing only)")
    ap.add_argument("--size", type=int, default=128, help="prior-only sweep grid side (128)")
    ap.add_argument("--scene", type=int, default=200, help="posterior sweep scene side (200)")
    ap.add_argument("--rounds", type=int, default=5, help="interleaved timing rounds (5)")
    ap.add_argument("--field-pl", action="store_true", help="also score the pattern field's PL stage (~1 min)")
    args = ap.parse_args()
    t0 = time.perf_counter()
    n = args.size
    net = net_from_file(args.net, (n, n)) if args.net else random_net((n, n))
    field = prior_by_name("field:houseexpo", (n, n))
    plans = load_training_plans("houseexpo")
    plan = next(plans.maps([9]))  # a validation plan
    occ = plan.occupancy
    r0, c0 = max((occ.shape[0] - n) // 2, 0), max((occ.shape[1] - n) // 2, 0)
    start = np.zeros((n, n), np.uint8)
    crop = occ[r0 : r0 + n, c0 : c0 + n]
    start[: crop.shape[0], : crop.shape[1]] = crop
    print(f"net field: {net!r} ({args.net or 'random, seeded'}); pattern field: field:houseexpo (w = 3)")
    payload: dict = {
        "net": args.net or "random (seeded)",
        "net_w": net.w,
        "net_units": 8 * net.hidden,
        "net_activation": net.activation,
        "prior_sweeps": prior_sweeps(field, net, start.ravel(), args.rounds),
        "posterior_sweeps": posterior_sweeps(net, args.scene, max(args.rounds - 2, 2)),
    }
    if args.net:
        payload["heldout_nll"] = scores(net, net.w, args.field_pl)
    payload["seconds"] = time.perf_counter() - t0
    path = write_json("bench_net_field", payload)
    print(f"wrote {path} ({payload['seconds']:.0f} s)")
    return payload


if __name__ == "__main__":
    main()
