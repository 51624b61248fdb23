"""A run of the VI-against-MCMC comparison (:mod:`ogm_ppl.studies.vi_vs_mcmc`): every problem of the settings,
every method on each, after the compiled kernels are warmed up."""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import asdict
from functools import partial

from ogm_ppl._dtype import float64
from ogm_ppl.inference.mcmc import CellGibbs, PatchGibbs
from ogm_ppl.inference.variational.guides import MeanFieldGuide, PatchGuide, fit_guide
from ogm_ppl.inference.variational.structured_guides import FirstHitGuide
from ogm_ppl.priors import IndependentPrior
from ogm_ppl.studies.vi_vs_mcmc.problems import (
    PROBLEMS_2D,
    grid_4x4,
    marginals_1d,
    marginals_brute_force,
    run_single,
    toy_problem,
)
from ogm_ppl.studies.vi_vs_mcmc.records import Settings
from ogm_ppl.studies.vi_vs_mcmc.report import TITLES, headlines
from ogm_ppl.studies.vi_vs_mcmc.walls import run_walls

__all__ = ["run"]


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


def run(cfg: Settings, seed: int = 0, log: Callable[[str], None] | None = None) -> dict:
    """Every problem in ``cfg.problems``, in float64 (the default dtype is restored after):
    ``{"seed", "settings", "problems": {name: {"latent", "records": [Record], "seconds", ...}}, "seconds",
    "headlines"}``. ``log`` gets a line per problem and per method (none by default). Times are wall clock;
    the caller sets the threads (one, for the numbers of the docs)."""
    with float64():
        return _run(cfg, seed, log or (lambda line: None))


def _run(cfg: Settings, seed: int, log: Callable[[str], None]) -> dict:
    t0 = time.perf_counter()
    _warm_up()
    problems: dict = {}
    for key in cfg.problems:
        log(f"{key}: {TITLES.get(key, key)}")
        t = time.perf_counter()
        if key == "toy":
            model = toy_problem()
            problems[key] = run_single(key, model, partial(marginals_1d, model), cfg, seed, log)
        elif key == "walls":
            problems[key] = run_walls(cfg, seed, log)
        else:  # Settings admits the problems of PROBLEMS only
            model = PROBLEMS_2D[key][1]()
            problems[key] = run_single(key, model, partial(marginals_brute_force, model), cfg, seed, log)
        problems[key]["seconds"] = time.perf_counter() - t
        log(f"  {key} done in {problems[key]['seconds']:.0f} s")
    res = {"seed": seed, "settings": asdict(cfg), "problems": problems, "seconds": time.perf_counter() - t0}
    res["headlines"] = headlines(res)
    return res
