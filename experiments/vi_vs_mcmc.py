"""One comparison harness: summed KL to the exact posterior against wall-clock time for
every method, on the 1D toy, on the 1000 wall datasets and on small 2D problems solved by brute force.

Methods. One pass: traditional OGM (Hähnel, the fitted p21 and the fitted neural update term of Section 2.5),
online / offline / overlapping patch maps (Chapter 3, independent priors only), the amortised 2D guide
(``ogm_ppl/fitted/guide_amortised.npz``, its one-pass marginals). Anytime (a curve of KL against seconds):
single-cell Gibbs (heat bath and metropolised), patch Gibbs (Chapter 4), Gibbs mixed with amortised-guide
block proposals (2D), and every Pyro guide with every objective that applies (mean field, patch, first hit;
``TraceGraph_ELBO``, ``ReweightedWakeSleep``, the closed-form ``ExactELBO``).

Problems.

* ``toy``: ``toy_1d(num_cells=21, readings=THESIS_TOY_READINGS)``, ``GaussianRange(3.0, p_rand=1e-3)``,
  ``IndependentPrior(0.5)``; exact by :func:`~ogm_ppl.inference.exact.pose_constrained_1d`.
* ``walls``: :func:`~ogm_ppl.datasets.wall_datasets` (1000 datasets, F = 75, wall 60, sigma 3, 1..10
  readings, seed 0, uniform prior, ``p_rand = 0``: the thesis's exact posteriors). Closed-form methods and
  cell Gibbs on every dataset; patch Gibbs and VI on the first datasets (counts in the table). VI needs
  finite log-likelihoods (a map with no wall has zero likelihood under ``p_rand = 0``), so it fits
  ``p_rand = 1e-300``, whose exact posterior is the thesis's to float precision (the KL is in the table).
  A larger floor is no good: at ``p_rand = 1e-30`` a reading explained as random (``log(1e-30 / 76)``)
  beats a wall 60 cells away under the uniform prior (``60 log 2``), the mean-field ELBO is flat at
  ``q = 1/2`` and its fit never moves. p21 and the neural update term are *cross-fitted*: each
  dataset is scored by a fit on the other folds (``--folds``), never on itself. Held-out cross-entropy:
  the same out-of-fold fits, and the shipped artefacts (fitted on all 1000) on fresh datasets (seed 1).
* ``2d:*``: 4 x 4 grids (13-15 latent cells), brute force: the independent prior and the 8-neighbour MRF
  fitted to HouseExpo (``mrf8:houseexpo``) under five single-beam scans (``GaussianRange(0.8, 1e-3)``), and
  one 120-beam 360 degree scan of a map drawn from the tile prior ``patch3:generated``
  (``GaussianRange(1.0, 1e-3)``), the amortised guide's training family apart from the grid size.

Times are wall clock on this machine (one thread), warm caches, excluding the KL evaluation. Writes
``out/vi_vs_mcmc/results.json``, ``table.md`` and ``kl_vs_time.png``.

    python experiments/vi_vs_mcmc.py            # about 7 minutes on 2 shared cores
    python experiments/vi_vs_mcmc.py --quick    # small settings, under a minute
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np
import pyro
import torch

from ogm_ppl import GaussianRange, Grid, OccupancyModel, Scans, raycast
from ogm_ppl.datasets import THESIS_TOY_READINGS, toy_1d, wall_datasets
from ogm_ppl.inference.exact import brute_force, pose_constrained_1d
from ogm_ppl.inference.log_odds import evidence_grid
from ogm_ppl.inference.mcmc import CellGibbs, PatchGibbs
from ogm_ppl.inference.patch_map import offline_patch_map, online_patch_map
from ogm_ppl.inference.variational.delta_fit import cross_entropy_loss, fit_delta
from ogm_ppl.inference.variational.guides import MeanFieldGuide, PatchGuide, fit_guide
from ogm_ppl.inference.variational.structured_guides import ExactELBO, FirstHitGuide
from ogm_ppl.io import atomic_write, atomic_write_text
from ogm_ppl.metrics import cross_entropy, kl_divergence
from ogm_ppl.models.delta import PN, NeuralDelta, delta_by_name
from ogm_ppl.priors import IndependentPrior
from ogm_ppl.priors.named import prior_by_name

ROOT = Path(__file__).resolve().parent.parent
EPS = 1e-9  # estimates are clamped to [EPS, 1 - EPS] before the KL (a sampler's 0/1 frequencies)
TARGET = 0.01  # the target accuracy: within 0.01 summed KL of exact
WALLS = dict(F=75, wall=60, sigma=3.0, num_readings=(1, 10))


@dataclass
class Settings:
    """Sizes of the run (``--quick``: :data:`QUICK`)."""

    vi_steps: int = 600  # closed-form (ExactELBO) fits, 1D toy and 2D
    vi_steps_sampled: int = 300  # TraceGraph_ELBO / RWS fits, 1D toy and 2D
    particles_tracegraph: int = 128
    particles_rws: int = 256
    toy_gibbs_sweeps: int = 100_000  # cell Gibbs (one compiled call per checkpoint)
    gibbs_sweeps: int = 10_000  # patch Gibbs and 2D kernels (one Python call per sweep)
    walls: int = 1000
    folds: int = 5
    walls_gibbs_sweeps: int = 1000  # cell Gibbs on every dataset
    walls_patch_gibbs: int = 50  # datasets for patch Gibbs
    walls_patch_gibbs_sweeps: int = 300
    walls_vi_exact: int = 4  # datasets for the ExactELBO guides
    walls_vi_sampled: int = 2  # datasets for the sampled objectives
    walls_vi_steps: int = 1000
    walls_vi_steps_sampled: int = 100
    heldout: int = 1000  # fresh wall datasets (seed + 1) for the shipped artefacts
    delta_max_iter: int = 500
    problems: tuple[str, ...] = ("toy", "walls", "2d:independent", "2d:mrf8", "2d:patch3")


QUICK = Settings(
    vi_steps=100,
    vi_steps_sampled=30,
    particles_tracegraph=32,
    particles_rws=64,
    toy_gibbs_sweeps=10_000,
    gibbs_sweeps=1000,
    walls=50,
    folds=2,
    walls_gibbs_sweeps=300,
    walls_patch_gibbs=5,
    walls_patch_gibbs_sweeps=100,
    walls_vi_exact=2,
    walls_vi_sampled=1,
    walls_vi_steps=60,
    walls_vi_steps_sampled=20,
    heldout=50,
    delta_max_iter=100,
)


def budgets(total: int, start: int = 10) -> list[int]:
    """Checkpoints 10, 30, 100, 300, ... up to ``total`` (``total`` always last)."""
    out, b = [], start
    while b < total:
        out.append(b)
        b = b * 3 if str(b).startswith("1") else b * 10 // 3
    return [*out, int(total)]


def summed_kl(exact: torch.Tensor, q: torch.Tensor, latent: torch.Tensor) -> float:
    """Summed cell ``KL(exact || q)`` over the latent cells, ``q`` clamped to ``[EPS, 1 - EPS]``."""
    q = torch.as_tensor(q, dtype=torch.float64).detach()
    return float(kl_divergence(exact[latent], q[latent].clamp(EPS, 1 - EPS)))


@dataclass
class Record:
    """One method on one problem: the final summed KL and seconds, and for anytime methods the curve
    ``[(budget, seconds, kl)]`` (budget in sweeps or steps)."""

    method: str
    kind: str  # "exact", "one pass", "anytime"
    kl: float
    seconds: float
    curve: list = field(default_factory=list)
    unit: str = ""
    note: str = ""
    datasets: int = 1

    def time_to(self, target: float = TARGET) -> float | None:
        """Seconds until the curve (or the one-pass estimate) first comes within ``target``."""
        pts = self.curve or [(0, self.seconds, self.kl)]
        return next((s for _, s, k in pts if k <= target), None)


# ------------------------------------------------------------------------------------------- methods
def _timed(fn):
    t = time.perf_counter()
    out = fn()
    return out, time.perf_counter() - t


def _unknown(model: OccupancyModel) -> float:
    lo = model.prior.cell_log_odds()
    return float(torch.sigmoid(lo[model.latent]).mean()) if lo is not None else 0.5


def one_pass(model: OccupancyModel, exact: torch.Tensor, name: str, fn, note: str = "", warm: bool = True) -> Record:
    """A one-pass estimate ``fn() -> K probabilities``, timed warm (``warm``: a first, untimed call
    compiles and fills caches)."""
    if warm:
        fn()
    q, dt = _timed(fn)
    return Record(name, "one pass", summed_kl(exact, q, model.latent), dt, note=note)


def ogm_methods(model: OccupancyModel, deltas: dict | None = None) -> dict:
    """Traditional OGM (Section 2.4) with each update term: name -> (fn, note)."""
    deltas = deltas or {
        "haehnel": delta_by_name("haehnel"),
        "p21": delta_by_name("p21"),
        "neural": delta_by_name("neural_opt"),
    }
    lam = _unknown(model)
    notes = {
        "p21": "fitted on the walls (F = 75, sigma = 3); a function of kappa - z only",
        "neural": "fitted on the walls (readings near 60 of F = 75): extrapolates in z / F here",
    }
    out = {}
    for key, d in deltas.items():
        label = {"haehnel": "OGM Hähnel", "p21": "OGM p21", "neural": "OGM neural Delta (amortised 1D)"}[key]
        out[label] = (lambda d=d: evidence_grid(model.rays, d, prior=lam).probabilities, notes.get(key, ""))
    return out


def patch_map_methods(model: OccupancyModel) -> dict:
    """Chapter 3's patch maps for this grid: name -> fn (needs a prior with independent cells)."""
    if model.prior.cell_log_odds() is None:
        return {}
    if model.grid.ndim == 1:
        out = {}
        for L in (3, 5):
            out[f"online patch map L={L}"] = lambda L=L: online_patch_map(model, L, offset=1).marginals
            out[f"offline patch map L={L}"] = lambda L=L: offline_patch_map(model, L, offset=1).marginals
            out[f"offline overlap L={L}"] = lambda L=L: offline_patch_map(model, L, overlap=True).marginals
        return out
    return {
        "online patch map 2x2": lambda: online_patch_map(model, (2, 2)).marginals,
        "offline patch map 2x2": lambda: offline_patch_map(model, (2, 2)).marginals,
        "offline overlap 3x3": lambda: offline_patch_map(model, (3, 3), overlap=True).marginals,
    }


_GUIDE: dict = {}


def amortised_guide():
    """The shipped amortised 2D guide, or the reason it is not available."""
    if "guide" not in _GUIDE:
        try:
            from ogm_ppl.inference.variational.amortised import shipped_guide

            _GUIDE["guide"], _GUIDE["why"] = shipped_guide(), ""
        except Exception as e:  # not importable, artefact missing or refused
            _GUIDE["guide"], _GUIDE["why"] = None, f"not available ({type(e).__name__}: {e})"
    return _GUIDE["guide"], _GUIDE["why"]


def guide_note(problem: str) -> str:
    guide, why = amortised_guide()
    if guide is None:
        return why
    t = guide.trained_for
    trained = f"trained for {t.get('prior')}, {t.get('sensor')}, {t.get('beams')}-beam scans, grids {t.get('sizes')}"
    if problem == "2d:patch3":
        return f"{trained}: same prior and scans, grid 4 x 4 (smaller), p_rand 1e-3"
    return f"{trained}: mismatched here"


def gibbs_curve(name: str, kernel, model: OccupancyModel, exact: torch.Tensor, sweeps: list[int], seed: int) -> Record:
    """Running marginals of one chain after each number of ``sweeps`` (set-up and sweeps timed; the
    compiled many-sweep path for cell Gibbs on independent priors)."""
    torch.manual_seed(seed)
    t0 = time.perf_counter()
    kernel.setup()
    elapsed = time.perf_counter() - t0
    fast = type(kernel) is CellGibbs and model.prior.cell_log_odds() is not None
    acc = torch.zeros(model.num_cells, dtype=torch.float64)
    done, curve = 0, []
    params = kernel.initial_params
    for i, b in enumerate(sweeps):
        t = time.perf_counter()
        if fast:
            acc += kernel.run_marginals(b - done, seed=seed * 1009 + i) * (b - done)
        else:
            for _ in range(b - done):
                params = kernel.sample(params)
                acc += model.full_map(params["m"])
        elapsed += time.perf_counter() - t
        done = b
        curve.append((b, elapsed, summed_kl(exact, acc / done, model.latent)))
    return Record(name, "anytime", curve[-1][2], curve[-1][1], curve, "sweeps")


def gibbs_methods(model: OccupancyModel, problem: str) -> dict:
    """name -> kernel factory."""
    patch = 3 if model.grid.ndim == 1 else (2, 2)
    tag = "L=3" if model.grid.ndim == 1 else "2x2"
    out = {
        "Gibbs (cell, heat bath)": lambda: CellGibbs(model, update="gibbs"),
        "Gibbs (cell, metropolised)": lambda: CellGibbs(model, update="metropolised"),
        f"patch Gibbs {tag}": lambda: PatchGibbs(model, patch),
    }
    if problem == "2d:patch3":
        out["patch Gibbs 3x3 (the prior's tiles)"] = lambda: PatchGibbs(model, (3, 3))
    guide, _ = amortised_guide()
    if guide is not None and model.grid.ndim == 2:
        from ogm_ppl.inference.mcmc.guided import GuidedGibbs

        out["guided Gibbs (cell + guide 2x2 blocks)"] = lambda: GuidedGibbs(CellGibbs(model), guide, block=(2, 2))
    return out


def _objective(loss: str, particles: int):
    from pyro.infer import ReweightedWakeSleep, TraceGraph_ELBO

    if loss == "tracegraph":
        return TraceGraph_ELBO(num_particles=particles, vectorize_particles=True, max_plate_nesting=0)
    if loss == "rws":
        return ReweightedWakeSleep(
            num_particles=particles, insomnia=1.0, model_has_params=False, vectorize_particles=True, max_plate_nesting=0
        )
    return ExactELBO()


def vi_curve(
    name: str,
    model: OccupancyModel,
    guide,
    loss: str,
    steps: int,
    lr: float,
    particles: int,
    exact: torch.Tensor,
    seed: int,
) -> Record:
    """``SVI(model.model, guide, Adam(lr), loss)`` as :func:`fit_guide` runs it, the guide's marginals
    scored at checkpoints (the SVI steps timed, the scoring not)."""
    from pyro.infer import SVI
    from pyro.optim import Adam

    fit_guide(model, guide, steps=0, loss=loss)  # fit_guide's checks (a likelihood without zeros)
    pyro.set_rng_seed(seed)
    svi = SVI(model.model, guide, Adam({"lr": lr}), _objective(loss, particles))
    curve, elapsed, done = [], 0.0, 0
    for b in budgets(steps):
        t = time.perf_counter()
        for _ in range(b - done):
            svi.step()
        elapsed += time.perf_counter() - t
        done = b
        q = guide.marginals()
        if torch.isnan(q).any():
            return Record(name, "anytime", math.nan, elapsed, curve, "steps", f"diverged: NaN parameters by step {b}")
        curve.append((b, elapsed, summed_kl(exact, q, model.latent)))
    return Record(name, "anytime", curve[-1][2], curve[-1][1], curve, "steps")


def vi_runs(model: OccupancyModel, cfg: Settings, steps_exact: int, steps_sampled: int, objectives=None) -> list:
    """(label, guide factory, loss, steps, lr, particles) for this model (ExactELBO needs an
    independent prior; the first-hit guide a common ray; the sampled objectives a likelihood without
    zeros)."""
    one_ray = model.grid.ndim == 1
    independent = model.prior.cell_log_odds() is not None
    patch = 2 if one_ray else (2, 2)
    tag = "L=2" if one_ray else "2x2"
    guides = [("mean field", MeanFieldGuide, True), (f"patch {tag}", lambda m: PatchGuide(m, patch), False)]
    if one_ray:
        guides.append(("first hit", FirstHitGuide, True))
    out = []
    for label, make, has_exact in guides:
        for loss in objectives or ("tracegraph", "rws", "exact"):
            if loss == "exact" and not (has_exact and independent):
                continue
            if loss == "exact":
                out.append((f"VI {label}, exact ELBO", make, loss, steps_exact, 0.1, 1))
            elif loss == "tracegraph":
                out.append((f"VI {label}, TraceGraph", make, loss, steps_sampled, 0.1, cfg.particles_tracegraph))
            else:
                out.append((f"VI {label}, RWS", make, loss, steps_sampled, 0.05, cfg.particles_rws))
    return out


# ------------------------------------------------------------------------------------------- problems
def toy_problem():
    toy = toy_1d(num_cells=21, readings=THESIS_TOY_READINGS)
    return OccupancyModel(
        toy.grid, raycast(toy.grid, toy.scans), GaussianRange(3.0, p_rand=1e-3), IndependentPrior(0.5, 21)
    )


def grid_4x4(prior) -> OccupancyModel:
    """``benchmarks/bench_mixing.py``'s 4 x 4 grid: five single-beam scans from three poses (13 latent)."""
    grid = Grid((4, 4), resolution=1.0)
    scans = Scans(
        [[0.5, 0.5, 0.0], [0.5, 0.5, 0.7], [3.5, 3.5, math.pi], [3.5, 3.5, -2.0], [0.5, 3.5, -0.6]],
        [0.0],
        [[2.6], [3.3], [2.2], [1.3], [2.9]],
        max_range=4.0,
        over_range="max",
    )
    return OccupancyModel(grid, raycast(grid, scans), GaussianRange(0.8, p_rand=1e-3), prior)


def patch3_scene(seed: int = 2) -> OccupancyModel:
    """One 120-beam 360 degree scan (range 12 cells) of a 4 x 4 map drawn from ``patch3:generated`` given
    the pose cell free (15 latent cells); seed 2 gives a map with 9 occupied cells."""
    from ogm_ppl.inference.variational.amortised import random_scene

    prior = prior_by_name("patch3:generated", (4, 4))
    scene = random_scene(prior, (4, 4), 1, 120, 12.0, GaussianRange(1.0, p_rand=1e-3), np.random.default_rng(seed))
    m0 = scene.model()
    gen = torch.Generator().manual_seed(seed)
    truth = m0.prior.sample_given_free(m0.known_free, (), generator=gen)
    return scene.model(m0.simulate_readings(truth, generator=gen))


PROBLEMS_2D = {
    "2d:independent": (
        "4 x 4, independent prior 0.4, five single-beam scans",
        lambda: grid_4x4(IndependentPrior(0.4, 16)),
    ),
    "2d:mrf8": (
        "4 x 4, MRF prior mrf8:houseexpo (correlated), five single-beam scans",
        lambda: grid_4x4(prior_by_name("mrf8:houseexpo", (4, 4))),
    ),
    "2d:patch3": ("4 x 4, tile prior patch3:generated (correlated), one 120-beam scan", patch3_scene),
}


def run_single(problem: str, model: OccupancyModel, exact_fn, cfg: Settings, seed: int, log) -> dict:
    """Every method on one model with one exact posterior."""
    exact, t_exact = _timed(exact_fn)
    recs = [Record("exact", "exact", 0.0, t_exact)]
    for name, (fn, note) in ogm_methods(model).items():
        recs.append(one_pass(model, exact, name, fn, note))
    for name, fn in patch_map_methods(model).items():
        recs.append(one_pass(model, exact, name, fn))
    guide, why = amortised_guide()
    if guide is not None:
        recs.append(
            one_pass(
                model, exact, "amortised guide (2D CNN, one pass)", lambda: guide.marginals(model), guide_note(problem)
            )
        )
    else:
        recs.append(Record("amortised guide (2D CNN, one pass)", "one pass", math.nan, math.nan, note=why))
    for name, make in gibbs_methods(model, problem).items():
        fast = "cell" in name and "guided" not in name and model.prior.cell_log_odds() is not None
        total = cfg.toy_gibbs_sweeps if (fast and problem == "toy") else cfg.gibbs_sweeps
        total = total // 3 if name.startswith("guided") else total  # its guide passes cost ~20 sweeps each
        recs.append(gibbs_curve(name, make(), model, exact, budgets(total), seed))
        log(f"  {name}: KL {recs[-1].kl:.2e} in {recs[-1].seconds:.2f} s")
    for label, make, loss, steps, lr, particles in vi_runs(model, cfg, cfg.vi_steps, cfg.vi_steps_sampled):
        recs.append(vi_curve(label, model, make(model), loss, steps, lr, particles, exact, seed))
        log(f"  {label}: KL {recs[-1].kl:.2e} in {recs[-1].seconds:.2f} s")
    return {"latent": len(model.latent), "records": recs}


# ------------------------------------------------------------------------------------------- walls
def wall_model(readings, p_rand: float = 0.0) -> OccupancyModel:
    K = WALLS["F"] + 1
    toy = toy_1d(num_cells=K, wall=WALLS["wall"], readings=readings, max_range=WALLS["F"])
    return OccupancyModel(
        toy.grid, raycast(toy.grid, toy.scans), GaussianRange(WALLS["sigma"], p_rand=p_rand), IndependentPrior(0.5, K)
    )


def _mean_records(name: str, recs: list[Record], note: str = "") -> Record:
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


def cross_fit(data, folds: int, max_iter: int, log) -> tuple[list[dict], dict]:
    """p21 and the neural update term fitted on all folds but one, for each fold: the families
    per dataset and the held-out cross-entropy per fold."""
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


def run_walls(cfg: Settings, seed: int, log) -> dict:
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
        exact, t_exact = _timed(lambda model=model: pose_constrained_1d(model).marginals)
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
                    lambda model=model: guide.marginals(model),
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
    heldout = {"entropy": H, "folds": cfg.folds, "datasets": len(data), "out_of_fold": {}, "fresh": {}}
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


# ------------------------------------------------------------------------------------------- output
TITLES = {
    "toy": "1D toy: 20 latent cells, thesis readings, GaussianRange(3.0, 1e-3), uniform prior",
    "walls": "1D wall datasets: F = 75, wall 60, sigma 3, 1..10 readings, uniform prior (means over datasets)",
    **{k: v[0] for k, v in PROBLEMS_2D.items()},
}


def _fmt(x, spec=".2e") -> str:
    if x is None or (isinstance(x, float) and math.isnan(x)):
        return "-"
    return format(x, spec)


def table_md(res: dict) -> str:
    lines = [
        "# Summed KL to the exact posterior against wall-clock time",
        "",
        f"`python experiments/vi_vs_mcmc.py{' --quick' if res['quick'] else ''}` (seed {res['seed']}), "
        f"{res['seconds']:.0f} s in all, one thread. Summed KL(exact || q) of the cell marginals over the latent "
        f"cells (estimates clamped to [{EPS:g}, 1 - {EPS:g}]); seconds: wall clock of the method (set-up "
        "included, scoring excluded; one-pass methods timed warm). OGM starts from the prior's lambda "
        "(0.5 for the correlated priors). Anytime methods: their last budget, "
        f'and the first time their curve came within {TARGET} ("t(KL<{TARGET})").',
        "",
    ]
    for h in res.get("headlines", []):
        lines.append(f"* {h}")
    for key, prob in res["problems"].items():
        lines += ["", f"## {key}: {TITLES.get(key, key)}", ""]
        lines += [
            "| method | summed KL | seconds | t(KL<0.01) s | budget | datasets | note |",
            "|---|---:|---:|---:|---:|---:|---|",
        ]
        for r in prob["records"]:
            r = r if isinstance(r, Record) else Record(**r)
            budget = f"{r.curve[-1][0]} {r.unit}" if r.curve else ""
            t_to = None if r.kind == "exact" else r.time_to()
            lines.append(
                f"| {r.method} | {_fmt(r.kl)} | {_fmt(r.seconds, '.3g')} | {_fmt(t_to, '.3g')} | "
                f"{budget} | {r.datasets} | {r.note} |"
            )
        if "heldout" in prob:
            h = prob["heldout"]
            lines += [
                "",
                "### Held-out cross-entropy on the wall datasets (nats per dataset, cells 1..F)",
                "",
                f"Out of fold: {h['folds']}-fold cross-fitting on the {h['datasets']} datasets (seed 0); "
                f"KL = cross-entropy - exact entropy ({h['entropy']:.4f}).",
                "",
                "| update term | held-out cross-entropy (mean +- sd over folds) | summed KL |",
                "|---|---:|---:|",
            ]
            for name, v in h["out_of_fold"].items():
                lines.append(f"| {name} | {v['ce']:.4f} +- {v['ce_sd_folds']:.4f} | {v['kl']:.4f} |")
            f = h["fresh"]
            lines += [
                "",
                f"Shipped artefacts (fitted on all 1000 seed-0 datasets) on {f['datasets']} fresh datasets "
                f"(seed 1; exact entropy {f['entropy']:.4f}):",
                "",
                "| update term | cross-entropy | summed KL |",
                "|---|---:|---:|",
            ]
            for name, v in f.items():
                if isinstance(v, dict):
                    lines.append(f"| {name} | {v['ce']:.4f} | {v['kl']:.4f} |")
    lines += ["", "![KL against time](kl_vs_time.png)", ""]
    return "\n".join(lines)


def headlines(res: dict) -> list[str]:
    out = []
    toy = res["problems"].get("toy")
    if toy:
        vis = [r for r in toy["records"] if r.method.startswith("VI")]
        best = min(vis, key=lambda r: r.kl)
        mf = [r.kl for r in vis if r.method.startswith("VI mean field")]
        t = best.time_to()
        out.append(
            f"1D toy: best guide {best.method}, summed KL {best.kl:.2e} after {best.curve[-1][0]} steps, "
            f"{best.seconds:.2f} s"
            + (f" (within {TARGET} after {t:.2f} s)" if t is not None else "")
            + f"; mean field {min(mf):.2e}..{max(mf):.2e} over its objectives."
        )
        g = next(r for r in toy["records"] if r.method == "Gibbs (cell, heat bath)")
        out.append(
            f"1D toy: cell Gibbs {g.kl:.2e} after {g.curve[-1][0]} sweeps, {g.seconds:.2f} s"
            + (f" (within {TARGET} after {g.time_to():.3f} s)" if g.time_to() is not None else "")
            + "."
        )
    walls = res["problems"].get("walls")
    if walls:
        h = walls["heldout"]["out_of_fold"]
        p, n = h["p21 (refit, out of fold)"], h["neural Delta (refit, out of fold)"]
        out.append(
            f"Wall datasets, held-out cross-entropy (out of fold): neural Delta {n['ce']:.4f} against p21 "
            f"{p['ce']:.4f} (summed KL {n['kl']:.4f} against {p['kl']:.4f})."
        )
    return out


def style(method: str) -> dict:
    """Line and marker of a method: colour by family (VI: by guide), line style by objective."""
    if method.startswith("VI "):
        guide, _, objective = method[3:].partition(", ")
        colour = {"mean": "tab:red", "patch": "tab:purple", "first": "tab:blue"}[guide.split()[0]]
        ls, marker = {"TraceGraph": (":", "x"), "RWS": ("--", "^"), "exact ELBO": ("-", "o")}[objective]
        return dict(color=colour, ls=ls, marker=marker, ms=5, lw=1.4)
    one = dict(ls="none", ms=8)
    if method.startswith("OGM"):
        return dict(one, color="0.25", marker={"H": "o", "p": "s"}.get(method[4], "^"))
    if "patch map" in method or "overlap" in method:
        colour = "tab:orange" if "online" in method else ("saddlebrown" if "overlap" in method else "goldenrod")
        return dict(one, color=colour, marker="D" if ("L=5" in method or "3x3" in method) else "v")
    if method.startswith("amortised"):
        return dict(one, color="magenta", marker="*", ms=12)
    gibbs = {
        "Gibbs (cell, heat bath)": ("tab:green", "o"),
        "Gibbs (cell, metropolised)": ("darkgreen", "s"),
        "guided Gibbs (cell + guide 2x2 blocks)": ("olive", "X"),
    }
    colour, marker = gibbs.get(method, ("teal", "P") if "3x3" in method else ("tab:cyan", "D"))
    return dict(color=colour, ls="-", marker=marker, ms=5, lw=1.6)


def plot(res: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names: list[str] = []
    for prob in res["problems"].values():
        for r in prob["records"]:
            if r.kind != "exact" and not math.isnan(r.kl) and r.method not in names:
                names.append(r.method)
    probs = list(res["problems"].items())
    ncol = 3
    nrow = math.ceil((len(probs) + 1) / ncol)
    fig, axes = plt.subplots(nrow, ncol, figsize=(6.0 * ncol, 4.6 * nrow), squeeze=False)
    floor = 1e-6
    for ax, (key, prob) in zip(axes.flat, probs):
        for r in prob["records"]:
            if r.kind == "exact":
                if r.method == "exact":
                    ax.axvline(max(r.seconds, 1e-5), color="0.5", ls=":", lw=1)
                continue
            if math.isnan(r.kl):
                continue
            pts = r.curve or [(0, r.seconds, r.kl)]
            ax.plot([max(p[1], 1e-5) for p in pts], [max(p[2], floor) for p in pts], **style(r.method))
        ax.axhline(TARGET, color="k", lw=0.8, ls="--")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_title(f"{key}: {TITLES.get(key, key)}", fontsize=8.5)
        ax.set_xlabel("seconds (wall clock)")
        ax.set_ylabel("summed KL to exact")
        ax.grid(True, which="major", alpha=0.3)
    for ax in list(axes.flat)[len(probs) :]:
        ax.axis("off")
    handles = [plt.Line2D([], [], **style(n)) for n in names]
    handles += [plt.Line2D([], [], color="k", ls="--", lw=0.8), plt.Line2D([], [], color="0.5", ls=":")]
    labels = [*names, f"KL = {TARGET}", "exact posterior's time"]
    list(axes.flat)[-1].legend(handles, labels, loc="center", fontsize=7.5, frameon=False, ncol=1)
    fig.tight_layout()
    with atomic_write(path) as f:
        fig.savefig(f, format="png", dpi=110)
    plt.close(fig)


def load_results(path: Path) -> dict:
    """``results.json`` back as :func:`run` returned it (records as :class:`Record`)."""
    res = json.loads(Path(path).read_text())
    for prob in res["problems"].values():
        prob["records"] = [
            Record(
                **{
                    k: (math.nan if v is None and k in ("kl", "seconds") else v)
                    for k, v in r.items()
                    if k != "time_to_kl_0.01"
                }
            )
            for r in prob["records"]
        ]
    return res


def _warm_up() -> None:
    """Compile the kernels once (numba) so that no method's time includes compilation."""
    model = toy_problem()
    for k in (CellGibbs(model), CellGibbs(model, update="metropolised"), PatchGibbs(model, 3)):
        k.setup()
        k.sample(k.initial_params)
    CellGibbs(model).run_marginals(2)
    m2 = grid_4x4(IndependentPrior(0.4, 16))
    for k in (CellGibbs(m2), PatchGibbs(m2, (2, 2))):
        k.setup()
        k.sample(k.initial_params)
    for make, loss in (
        (MeanFieldGuide, "exact"),
        (FirstHitGuide, "exact"),
        (MeanFieldGuide, "tracegraph"),
        (lambda m: PatchGuide(m, 2), "rws"),
    ):
        fit_guide(model, make(model), steps=2, num_particles=4, loss=loss)


def run(cfg: Settings, seed: int = 0, log=print) -> dict:
    """Every problem in ``cfg.problems``: {"problems": {name: {"records": [Record], ...}}, ...}."""
    t0 = time.perf_counter()
    torch.set_default_dtype(torch.float64)
    _warm_up()
    problems: dict = {}
    for key in cfg.problems:
        log(f"{key}: {TITLES.get(key, key)}")
        t = time.perf_counter()
        if key == "toy":
            model = toy_problem()
            problems[key] = run_single(
                key, model, lambda model=model: pose_constrained_1d(model).marginals, cfg, seed, log
            )
        elif key == "walls":
            problems[key] = run_walls(cfg, seed, log)
        elif key in PROBLEMS_2D:
            model = PROBLEMS_2D[key][1]()
            problems[key] = run_single(key, model, lambda model=model: brute_force(model).marginals, cfg, seed, log)
        else:
            raise ValueError(f"unknown problem {key!r}; known: toy, walls, {', '.join(PROBLEMS_2D)}")
        problems[key]["seconds"] = time.perf_counter() - t
        log(f"  {key} done in {problems[key]['seconds']:.0f} s")
    res = {"seed": seed, "settings": asdict(cfg), "problems": problems, "seconds": time.perf_counter() - t0}
    res["headlines"] = headlines(res)
    return res


def to_json(res: dict) -> str:
    def enc(o):
        if isinstance(o, Record):
            d = asdict(o)
            d["time_to_kl_0.01"] = o.time_to()
            return {k: None if isinstance(v, float) and math.isnan(v) else v for k, v in d.items()}
        raise TypeError(type(o).__name__)

    return json.dumps(res, indent=1, default=enc, allow_nan=True)


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="small settings (under a minute)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument(
        "--problems", default=None, help="comma-separated subset of toy,walls,2d:independent,2d:mrf8,2d:patch3"
    )
    ap.add_argument("--out", default=str(ROOT / "out" / "vi_vs_mcmc"))
    ap.add_argument("--replot", action="store_true", help="redraw table.md and the figure from results.json")
    args = ap.parse_args(argv)
    out = Path(args.out)
    if args.replot:
        res = load_results(out / "results.json")
        atomic_write_text(out / "table.md", table_md(res))
        plot(res, out / "kl_vs_time.png")
        return res
    torch.set_num_threads(1)
    try:
        import numba

        numba.set_num_threads(1)
    except (ImportError, ValueError):
        pass
    cfg = QUICK if args.quick else Settings()
    if args.problems:
        cfg = replace(cfg, problems=tuple(p.strip() for p in args.problems.split(",")))
    res = run(cfg, args.seed, log=lambda s: print(s, file=sys.stderr, flush=True))
    res["quick"] = bool(args.quick)
    out.mkdir(parents=True, exist_ok=True)
    atomic_write_text(out / "results.json", to_json(res))
    md = table_md(res)
    atomic_write_text(out / "table.md", md)
    plot(res, out / "kl_vs_time.png")
    print(md)
    return res


if __name__ == "__main__":
    main()
