"""The methods of the VI-against-MCMC comparison (:mod:`ogm_ppl.studies.vi_vs_mcmc`), each timed and scored by
its summed KL to the exact posterior.

One pass (:func:`one_pass`): traditional OGM with each update term (:func:`ogm_methods`, thesis Sections
2.4-2.5), Chapter 3's patch maps (:func:`patch_map_methods`), the shipped amortised 2D guide
(:func:`amortised_guide`). Anytime: a Gibbs chain's running marginals after each budget of sweeps
(:func:`gibbs_curve` over the kernels of :func:`gibbs_methods`, Chapter 4), and a Pyro guide's marginals after
each budget of SVI steps (:func:`vi_curve` over the runs of :func:`vi_runs`: mean-field, patch and first-hit
guides with ``TraceGraph_ELBO``, ``ReweightedWakeSleep`` and the closed-form ``ExactELBO``).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from functools import partial
from typing import Any

import pyro
import torch

from ogm_ppl import OccupancyModel
from ogm_ppl.inference.log_odds import evidence_grid
from ogm_ppl.inference.mcmc import CellGibbs, PatchGibbs
from ogm_ppl.inference.patch_map import offline_patch_map, online_patch_map
from ogm_ppl.inference.variational.guides import MeanFieldGuide, PatchGuide, fit_guide
from ogm_ppl.inference.variational.structured_guides import ExactELBO, FirstHitGuide
from ogm_ppl.models.delta import delta_by_name
from ogm_ppl.studies.vi_vs_mcmc.records import Record, Settings, budgets, summed_kl

__all__ = [
    "amortised_guide",
    "gibbs_curve",
    "gibbs_methods",
    "guide_note",
    "ogm_methods",
    "one_pass",
    "patch_map_methods",
    "timed",
    "vi_curve",
    "vi_runs",
]

#: a one-pass method: no arguments, the ``(K,)`` marginals
Marginals = Callable[[], torch.Tensor]
#: one VI run of :func:`vi_runs`: ``(label, guide factory, loss, steps, lr, particles)``
VIRun = tuple[str, Callable[[OccupancyModel], Any], str, int, float, int]


def timed(fn: Callable[[], Any]) -> tuple[Any, float]:
    """``(fn(), seconds)``: the call timed by the wall clock."""
    t = time.perf_counter()
    out = fn()
    return out, time.perf_counter() - t


def _unknown(model: OccupancyModel) -> float:
    """The prior's mean cell probability over the latent cells (0.5 for a prior without cell log-odds)."""
    lo = model.prior.cell_log_odds()
    return float(torch.sigmoid(lo[model.latent]).mean()) if lo is not None else 0.5


def one_pass(
    model: OccupancyModel, exact: torch.Tensor, name: str, fn: Marginals, note: str = "", warm: bool = True
) -> Record:
    """A one-pass estimate ``fn() -> K probabilities`` scored against ``exact``, timed warm (``warm``: a first,
    untimed call compiles and fills caches)."""
    if warm:
        fn()
    q, dt = timed(fn)
    return Record(name, "one pass", summed_kl(exact, q, model.latent), dt, note=note)


def ogm_methods(model: OccupancyModel, deltas: dict | None = None) -> dict[str, tuple[Marginals, str]]:
    """Traditional OGM (Section 2.4) with each update term (``deltas``: ``{"haehnel", "p21", "neural"}`` to
    update-term families; default the shipped ones), from the prior's mean as the unknown probability:
    ``{label: (fn, note)}``."""
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
    out: dict[str, tuple[Marginals, str]] = {}
    for key, d in deltas.items():
        label = {"haehnel": "OGM Hähnel", "p21": "OGM p21", "neural": "OGM neural Delta (amortised 1D)"}[key]
        out[label] = (partial(_ogm, model, d, lam), notes.get(key, ""))
    return out


def _ogm(model: OccupancyModel, delta: Any, unknown: float) -> torch.Tensor:
    return evidence_grid(model.rays, delta, prior=unknown).probabilities


def _marginals(patch_map: Callable[..., Any], *args: Any, **kwargs: Any) -> torch.Tensor:
    return patch_map(*args, **kwargs).marginals


def patch_map_methods(model: OccupancyModel) -> dict[str, Marginals]:
    """Chapter 3's patch maps for this grid, ``{name: fn}``: online, offline and overlapping patches of 3 and 5
    cells in 1D, 2 x 2 and 3 x 3 in 2D (none for a prior without independent cells)."""
    if model.prior.cell_log_odds() is None:
        return {}
    if model.grid.ndim == 1:
        out: dict[str, Marginals] = {}
        for L in (3, 5):
            out[f"online patch map L={L}"] = partial(_marginals, online_patch_map, model, L, offset=1)
            out[f"offline patch map L={L}"] = partial(_marginals, offline_patch_map, model, L, offset=1)
            out[f"offline overlap L={L}"] = partial(_marginals, offline_patch_map, model, L, overlap=True)
        return out
    return {
        "online patch map 2x2": lambda: online_patch_map(model, (2, 2)).marginals,
        "offline patch map 2x2": lambda: offline_patch_map(model, (2, 2)).marginals,
        "offline overlap 3x3": lambda: offline_patch_map(model, (3, 3), overlap=True).marginals,
    }


_GUIDE: dict = {}  # the shipped guide, loaded once per process


def amortised_guide() -> tuple[Any, str]:
    """``(guide, "")``: the shipped amortised 2D guide, or ``(None, why)`` where it is not available."""
    if "guide" not in _GUIDE:
        try:
            from ogm_ppl.inference.variational.amortised import shipped_guide

            _GUIDE["guide"], _GUIDE["why"] = shipped_guide(), ""
        except Exception as e:  # not importable, artefact missing or refused
            _GUIDE["guide"], _GUIDE["why"] = None, f"not available ({type(e).__name__}: {e})"
    return _GUIDE["guide"], _GUIDE["why"]


def guide_note(problem: str) -> str:
    """What the shipped guide was trained for, against ``problem``'s model (or why there is no guide)."""
    guide, why = amortised_guide()
    if guide is None:
        return why
    t = guide.trained_for
    trained = f"trained for {t.get('prior')}, {t.get('sensor')}, {t.get('beams')}-beam scans, grids {t.get('sizes')}"
    if problem == "2d:patch3":
        return f"{trained}: same prior and scans, grid 4 x 4 (smaller), p_rand 1e-3"
    return f"{trained}: mismatched here"


def gibbs_curve(
    name: str, kernel: Any, model: OccupancyModel, exact: torch.Tensor, sweeps: Sequence[int], seed: int
) -> Record:
    """The running marginals of one chain of ``kernel`` (torch seed ``seed``) scored after each number of
    ``sweeps`` (set-up and sweeps timed, scoring not; the compiled many-sweep path for cell Gibbs on
    independent priors)."""
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


def gibbs_methods(model: OccupancyModel, problem: str) -> dict[str, Callable[[], Any]]:
    """The samplers for ``model``, ``{name: kernel factory}``: cell Gibbs (heat bath and metropolised), patch
    Gibbs (3 cells in 1D, 2 x 2 in 2D; 3 x 3 on ``2d:patch3``) and, with the shipped guide in 2D, cell Gibbs
    mixed with guide block proposals."""
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


def _objective(loss: str, particles: int) -> Any:
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
    guide: Any,
    loss: str,
    steps: int,
    lr: float,
    particles: int,
    exact: torch.Tensor,
    seed: int,
) -> Record:
    """``SVI(model.model, guide, Adam(lr), loss)`` as :func:`~ogm_ppl.inference.variational.guides.fit_guide`
    runs it (``loss``: ``"tracegraph"``, ``"rws"`` or ``"exact"``, with ``particles``), the guide's marginals
    scored at the checkpoints of :func:`~ogm_ppl.studies.vi_vs_mcmc.records.budgets` (the SVI steps timed, the
    scoring not); a guide whose parameters turn NaN ends the curve with a note."""
    from pyro.infer import SVI
    from pyro.optim import Adam

    fit_guide(model, guide, steps=0, loss=loss)  # fit_guide's checks (a likelihood without zeros)
    pyro.set_rng_seed(seed)
    svi = SVI(model.model, guide, Adam({"lr": lr}), _objective(loss, particles))
    curve: list[tuple[int, float, float]] = []
    elapsed, done = 0.0, 0
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


def vi_runs(
    model: OccupancyModel,
    cfg: Settings,
    steps_exact: int,
    steps_sampled: int,
    objectives: Sequence[str] | None = None,
) -> list[VIRun]:
    """``(label, guide factory, loss, steps, lr, particles)`` for this model and each of ``objectives``
    (default all three; ExactELBO needs an independent prior, the first-hit guide a common ray, the sampled
    objectives a likelihood without zeros)."""
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
