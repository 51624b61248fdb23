r"""The wall datasets of the VI-against-MCMC comparison (:mod:`ogm_ppl.studies.vi_vs_mcmc`): every method on
each of :func:`~ogm_ppl.datasets.wall_datasets` (F = 75, wall 60, sigma 3, 1..10 readings, seed 0, uniform
prior, ``p_rand = 0``: the thesis's exact posteriors), means over the datasets.

The closed-form methods and cell Gibbs run on every dataset; patch Gibbs and VI on the first datasets (counts in
the records). VI needs finite log-likelihoods (a map with no wall has zero likelihood under ``p_rand = 0``), so
it fits ``p_rand = 1e-300``, whose exact posterior is the thesis's to float precision (its KL is a record). A
larger floor is no good: at ``p_rand = 1e-30`` a reading explained as random (``log(1e-30 / 76)``) beats a wall
60 cells away under the uniform prior (``60 log 2``), the mean-field ELBO is flat at ``q = 1/2`` and its fit
never moves. p21 and the neural update term are *cross-fitted* (:func:`cross_fit`): each dataset is scored by a
fit on the other folds, never on itself. Held-out cross-entropy, in nats per dataset over cells ``1..F``,

.. math::

    H(p, q) = -\frac{1}{D} \sum_{d=1}^{D} \sum_{k=1}^{F} \big[ p_{dk} \log q_{dk} + (1 - p_{dk}) \log (1 - q_{dk}) \big]

for the same out-of-fold fits, and for the shipped artefacts (fitted on all 1000) on fresh datasets (seed 1);
its excess over the exact entropy ``H(p, p)`` is the summed KL.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from functools import partial
from typing import Any

import numpy as np
import torch

from ogm_ppl import GaussianRange, OccupancyModel, raycast
from ogm_ppl.datasets import toy_1d, wall_datasets
from ogm_ppl.inference.exact import pose_constrained_1d
from ogm_ppl.inference.mcmc import CellGibbs, PatchGibbs
from ogm_ppl.inference.variational.delta_fit import cross_entropy_loss, fit_delta
from ogm_ppl.metrics import cross_entropy
from ogm_ppl.models.delta import PN, NeuralDelta, delta_by_name
from ogm_ppl.priors import IndependentPrior
from ogm_ppl.studies.vi_vs_mcmc.methods import (
    amortised_guide,
    gibbs_curve,
    guide_note,
    ogm_methods,
    one_pass,
    patch_map_methods,
    timed,
    vi_curve,
    vi_runs,
)
from ogm_ppl.studies.vi_vs_mcmc.problems import marginals_1d
from ogm_ppl.studies.vi_vs_mcmc.records import EPS, WALLS, Record, Settings, budgets, summed_kl

__all__ = ["cross_fit", "run_walls", "wall_model"]


def wall_model(readings: Any, p_rand: float = 0.0) -> OccupancyModel:
    """The model of one wall dataset's ``readings``: ``F + 1`` cells, ``GaussianRange(3, p_rand)``, uniform prior."""
    K = WALLS["F"] + 1
    toy = toy_1d(num_cells=K, wall=WALLS["wall"], readings=readings, max_range=WALLS["F"])
    return OccupancyModel(
        toy.grid, raycast(toy.grid, toy.scans), GaussianRange(WALLS["sigma"], p_rand=p_rand), IndependentPrior(0.5, K)
    )


def _mean_records(name: str, recs: Sequence[Record], note: str = "") -> Record:
    """The mean over datasets of the KL and the seconds (and of the curves, point by point)."""
    curve = []
    if recs[0].curve:
        for pts in zip(*(r.curve for r in recs)):
            curve.append((pts[0][0], float(np.mean([p[1] for p in pts])), float(np.mean([p[2] for p in pts]))))
    return Record(
        name,
        recs[0].kind,
        float(np.mean([r.kl for r in recs])),
        float(np.mean([r.seconds for r in recs])),
        curve,
        recs[0].unit,
        note or recs[0].note,
        len(recs),
    )


def cross_fit(
    data: Any, folds: int, max_iter: int, log: Callable[[str], None]
) -> tuple[list[dict], dict[str, list[float]]]:
    """p21 and the neural update term fitted on all folds but one (contiguous folds of ``data``, the last
    taking the remainder), for each fold: ``(per dataset {"p21", "neural"}: the fits that never saw it,
    {update term: held-out cross-entropy per fold})``, Hähnel's and the thesis's p21 scored alongside."""
    D = len(data)
    size = D // folds
    per_dataset: list[dict] = [{} for _ in range(D)]
    ce: dict[str, list[float]] = {}
    fixed = {"Hähnel": delta_by_name("haehnel"), "p21 (thesis values)": delta_by_name("p21_thesis")}
    for k in range(folds):
        te = torch.arange(k * size, D if k == folds - 1 else (k + 1) * size)
        tr = torch.cat([torch.arange(0, k * size), torch.arange(int(te[-1]) + 1, D)])
        train, held = data.subset(tr), data.subset(te)
        fams = {
            "p21": fit_delta(PN.zeros(21), train, max_iter=max_iter).family,
            "neural": fit_delta(NeuralDelta(data.F, hidden=16, seed=0), train, max_iter=max_iter).family,
        }
        for i in te.tolist():
            per_dataset[i] = fams
        with torch.no_grad():
            for name, fam in {
                **fixed,
                "p21 (refit, out of fold)": fams["p21"],
                "neural Delta (refit, out of fold)": fams["neural"],
            }.items():
                ce.setdefault(name, []).append(float(cross_entropy_loss(fam, held)))
        log(
            f"  fold {k + 1}/{folds}: held-out CE p21 {ce['p21 (refit, out of fold)'][-1]:.4f}, "
            f"neural {ce['neural Delta (refit, out of fold)'][-1]:.4f}"
        )
    return per_dataset, ce


def _entropy(p: torch.Tensor) -> float:
    """Mean over datasets of the summed binary entropy of cells 1..F."""
    return float(cross_entropy(p[:, 1:], p[:, 1:]) / len(p))


def run_walls(cfg: Settings, seed: int, log: Callable[[str], None]) -> dict:
    """Every method on the first ``cfg.walls`` wall datasets (module docstring): ``{"latent": F, "records":
    [Record, means over datasets], "heldout": {"entropy", "folds", "datasets", "out_of_fold": {term: {"ce",
    "ce_sd_folds", "kl"}}, "fresh": {"datasets", "entropy", term: {"ce", "kl"}}}}``."""
    t = time.perf_counter()
    data = wall_datasets(num=cfg.walls, **WALLS, seed=0)
    log(f"  {len(data)} wall datasets with exact posteriors in {time.perf_counter() - t:.1f} s")
    per_dataset, ce_folds = cross_fit(data, cfg.folds, cfg.delta_max_iter, log)
    guide, why = amortised_guide()
    rec: dict[str, list[Record]] = {}

    def add(r: Record) -> None:
        rec.setdefault(r.method, []).append(r)

    for d in range(len(data)):
        model = wall_model(data.readings[d])
        exact, t_exact = timed(partial(marginals_1d, model))
        if not torch.allclose(exact, data.exact[d], atol=1e-9):
            raise RuntimeError(f"dataset {d}: exact posterior differs from the stored one")
        add(Record("exact", "exact", 0.0, t_exact))
        fams = per_dataset[d]
        deltas = {"haehnel": delta_by_name("haehnel"), "p21": fams["p21"], "neural": fams["neural"]}
        warm = d == 0  # later datasets find the kernels compiled; times are means over all datasets
        for name, (fn, _) in ogm_methods(model, deltas).items():
            add(one_pass(model, exact, name, fn, warm=warm))
        for name, fn in patch_map_methods(model).items():
            add(one_pass(model, exact, name, fn, warm=warm))
        if guide is not None:
            add(
                one_pass(
                    model,
                    exact,
                    "amortised guide (2D CNN, one pass)",
                    partial(guide.marginals, model),
                    warm=warm,
                )
            )
        for name in ("Gibbs (cell, heat bath)", "Gibbs (cell, metropolised)"):
            kernel = CellGibbs(model, update="gibbs" if "heat" in name else "metropolised")
            add(gibbs_curve(name, kernel, model, exact, budgets(cfg.walls_gibbs_sweeps), seed * 100_003 + d))
        if d < cfg.walls_patch_gibbs:
            add(
                gibbs_curve(
                    "patch Gibbs L=3",
                    PatchGibbs(model, 3),
                    model,
                    exact,
                    budgets(cfg.walls_patch_gibbs_sweeps),
                    seed * 100_003 + d,
                )
            )
        if d < max(cfg.walls_vi_exact, cfg.walls_vi_sampled):
            vi_model = wall_model(data.readings[d], p_rand=1e-300)
            floor = summed_kl(exact, pose_constrained_1d(vi_model).marginals, model.latent)
            add(Record("exact posterior under p_rand = 1e-300 (VI's model)", "exact", floor, 0.0))
            objectives = ["exact"] + (["tracegraph", "rws"] if d < cfg.walls_vi_sampled else [])
            for label, make, loss, steps, lr, particles in vi_runs(
                vi_model, cfg, cfg.walls_vi_steps, cfg.walls_vi_steps_sampled, objectives
            ):
                if d < (cfg.walls_vi_exact if loss == "exact" else cfg.walls_vi_sampled):
                    add(vi_curve(label, vi_model, make(vi_model), loss, steps, lr, particles, exact, seed))
            log(
                f"  VI on dataset {d + 1}: "
                + ", ".join(f"{k} {v[-1].kl:.2e}" for k, v in rec.items() if k.startswith("VI"))
            )
        if (d + 1) % max(len(data) // 10, 1) == 0:
            log(f"  {d + 1}/{len(data)} datasets")
    notes = {
        "OGM p21": f"cross-fitted ({cfg.folds} folds): each dataset scored by a fit that never saw it",
        "OGM neural Delta (amortised 1D)": f"cross-fitted ({cfg.folds} folds), MLP with 2 x 16 tanh units",
        "amortised guide (2D CNN, one pass)": guide_note("walls") if guide is not None else why,
        "exact posterior under p_rand = 1e-300 (VI's model)": "KL of VI's target to the thesis's exact posterior",
    }
    records = [_mean_records(name, rs, notes.get(name, "")) for name, rs in rec.items()]
    # held-out cross-entropy: out-of-fold fits, and the shipped artefacts on fresh datasets
    H = _entropy(data.exact)
    heldout: dict[str, Any] = {"entropy": H, "folds": cfg.folds, "datasets": len(data), "out_of_fold": {}, "fresh": {}}
    for name, v in ce_folds.items():
        heldout["out_of_fold"][name] = {
            "ce": float(np.mean(v)),
            "ce_sd_folds": float(np.std(v)),
            "kl": float(np.mean(v)) - H,
        }
    t = time.perf_counter()
    fresh = wall_datasets(num=cfg.heldout, **WALLS, seed=1)
    log(f"  {len(fresh)} fresh wall datasets (seed 1) in {time.perf_counter() - t:.1f} s")
    H1 = _entropy(fresh.exact)
    heldout["fresh"]["datasets"] = len(fresh)
    heldout["fresh"]["entropy"] = H1
    with torch.no_grad():
        for name, key in (
            ("Hähnel", "haehnel"),
            ("p21 (thesis values)", "p21_thesis"),
            ("p21 (shipped)", "p21"),
            ("neural Delta (shipped neural_opt)", "neural_opt"),
        ):
            ce = float(cross_entropy_loss(delta_by_name(key), fresh))
            heldout["fresh"][name] = {"ce": ce, "kl": ce - H1}
    if guide is not None:
        ces = []
        for d in range(len(fresh)):
            q = guide.marginals(wall_model(fresh.readings[d]))
            ces.append(float(cross_entropy(fresh.exact[d, 1:], q[1:].clamp(EPS, 1 - EPS))))
        heldout["fresh"]["amortised 2D guide (shipped)"] = {"ce": float(np.mean(ces)), "kl": float(np.mean(ces)) - H1}
    return {"latent": WALLS["F"], "records": records, "heldout": heldout}
