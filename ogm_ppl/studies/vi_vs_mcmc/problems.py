"""The problems of the VI-against-MCMC comparison with an exact posterior (:mod:`ogm_ppl.studies.vi_vs_mcmc`),
and every method run on one of them (:func:`run_single`).

* ``toy`` (:func:`toy_problem`): ``toy_1d(num_cells=21, readings=THESIS_TOY_READINGS)``,
  ``GaussianRange(3.0, p_rand=1e-3)``, ``IndependentPrior(0.5)``; exact by
  :func:`~ogm_ppl.inference.exact.pose_constrained_1d`.
* ``2d:*`` (:data:`PROBLEMS_2D`): 4 x 4 grids (13-15 latent cells), exact by brute force: the independent prior
  and the 8-neighbour MRF fitted to HouseExpo (``mrf8:houseexpo``) under five single-beam scans
  (:func:`grid_4x4`), and one 120-beam 360 degree scan of a map drawn from the tile prior ``patch3:generated``
  (:func:`patch3_scene`), the amortised guide's training family apart from the grid size.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
import torch

from ogm_ppl import GaussianRange, Grid, OccupancyModel, Scans, raycast
from ogm_ppl.datasets import THESIS_TOY_READINGS, toy_1d
from ogm_ppl.inference.exact import brute_force, pose_constrained_1d
from ogm_ppl.priors import IndependentPrior
from ogm_ppl.priors.named import prior_by_name
from ogm_ppl.studies.vi_vs_mcmc.methods import (
    amortised_guide,
    gibbs_curve,
    gibbs_methods,
    guide_note,
    ogm_methods,
    one_pass,
    patch_map_methods,
    timed,
    vi_curve,
    vi_runs,
)
from ogm_ppl.studies.vi_vs_mcmc.records import Record, Settings, budgets

__all__ = [
    "PROBLEMS_2D",
    "grid_4x4",
    "marginals_1d",
    "marginals_brute_force",
    "patch3_scene",
    "run_single",
    "toy_problem",
]

#: a line of progress
Log = Callable[[str], None]


def marginals_1d(model: OccupancyModel) -> torch.Tensor:
    """The exact marginals of a 1D model (:func:`~ogm_ppl.inference.exact.pose_constrained_1d`)."""
    return pose_constrained_1d(model).marginals


def marginals_brute_force(model: OccupancyModel) -> torch.Tensor:
    """The exact marginals of a small model by enumeration (:func:`~ogm_ppl.inference.exact.brute_force`)."""
    return brute_force(model).marginals


def toy_problem() -> OccupancyModel:
    """The 1D toy: 21 cells (20 latent), the thesis's readings, ``GaussianRange(3.0, 1e-3)``, uniform prior."""
    toy = toy_1d(num_cells=21, readings=THESIS_TOY_READINGS)
    return OccupancyModel(
        toy.grid, raycast(toy.grid, toy.scans), GaussianRange(3.0, p_rand=1e-3), IndependentPrior(0.5, 21)
    )


def grid_4x4(prior) -> OccupancyModel:
    """A 4 x 4 grid (1 m cells) under ``prior``: five single-beam scans from three poses, range 4 m,
    ``GaussianRange(0.8, 1e-3)`` (13 latent cells; the grid of ``benchmarks/bench_mixing.py``)."""
    grid = Grid((4, 4), resolution=1.0)
    scans = Scans(
        np.array([[0.5, 0.5, 0.0], [0.5, 0.5, 0.7], [3.5, 3.5, math.pi], [3.5, 3.5, -2.0], [0.5, 3.5, -0.6]]),
        np.array([0.0]),
        np.array([[2.6], [3.3], [2.2], [1.3], [2.9]]),
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


#: the 2D problems: ``{name: (title, model factory)}``
PROBLEMS_2D: dict[str, tuple[str, Callable[[], OccupancyModel]]] = {
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


def run_single(
    problem: str, model: OccupancyModel, exact_fn: Callable[[], torch.Tensor], cfg: Settings, seed: int, log: Log
) -> dict:
    """Every method on one model with one exact posterior (``exact_fn``, timed): ``{"latent": cells,
    "records": [Record]}``, the exact posterior first, then the one-pass methods, the samplers and the
    guides; ``log`` gets a line per anytime method."""
    exact, t_exact = timed(exact_fn)
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
    for label, make_guide, loss, steps, lr, particles in vi_runs(model, cfg, cfg.vi_steps, cfg.vi_steps_sampled):
        recs.append(vi_curve(label, model, make_guide(model), loss, steps, lr, particles, exact, seed))
        log(f"  {label}: KL {recs[-1].kl:.2e} in {recs[-1].seconds:.2f} s")
    return {"latent": len(model.latent), "records": recs}
