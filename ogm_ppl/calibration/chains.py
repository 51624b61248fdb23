r"""The methods of the calibration protocol run on one scene (thesis Sections 4.1 and 5.2.2): a prior's
chains, the traditional-OGM baseline and a corpus guide's one-pass marginals.

Chains. A prior runs ``C = 3`` chains (:data:`STARTS`: traditional OGM thresholded at the prior's mean, the
all-free map, a draw from the prior) of a sampler of :data:`KERNELS`, ``sweeps`` kept sweeps after ``burn``
warm-up sweeps each, from seeds ``seed + 1000 c``. The marginals scored are pooled over the chains,
``q = (1/C) sum_c q^(c)``; split R-hat (:func:`~ogm_ppl.inference.mcmc.diagnostics.split_rhat`) per unseen
cell over the chains' kept sweeps gives the share of unseen cells whose chains agree (:func:`agreeing`:
``R-hat < 1.05``, cells that keep one value in every sweep of every chain counted as agreeing).

The sampler of a prior (:func:`default_patch`): single-cell Gibbs when its compiled bundle weighs dense
conditionals, patch Gibbs over the prior's tile (``L = 9`` cells for the 3 x 3 tile priors, Algorithm 2) when
it weighs a sparse support; a prior whose update would weigh more than ``max_support`` configurations
(:func:`support`) is skipped.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping
from functools import lru_cache
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

from ogm_ppl.calibration.names import unbiased_name
from ogm_ppl.calibration.scenes import CalibrationScene, score_marginals
from ogm_ppl.inference import CellGibbs, PatchGibbs, RunningStats, evidence_grid, run_gibbs
from ogm_ppl.inference.mcmc import mixing_cycle
from ogm_ppl.inference.mcmc.diagnostics import split_rhat
from ogm_ppl.inference.mcmc.tempering import ParallelTempering, geometric_ladder
from ogm_ppl.models import OccupancyModel, delta_by_name
from ogm_ppl.priors import BiasedPrior
from ogm_ppl.priors.named import load_temper_params, prior_by_name, split_prior_name
from ogm_ppl.sensors import GaussianRange

if TYPE_CHECKING:
    from ogm_ppl.inference.mcmc.kernel import MapKernel
    from ogm_ppl.inference.variational.amortised import AmortisedGuide
    from ogm_ppl.priors.tables import PriorTables

__all__ = [
    "KERNELS",
    "RHAT_THRESHOLD",
    "STARTS",
    "ChainOptions",
    "KernelFactory",
    "agreeing",
    "cycle_kernel",
    "default_patch",
    "gibbs_kernel",
    "guided_kernel",
    "proposal_guide",
    "run_prior_chains",
    "run_guide",
    "run_ogm",
    "run_prior",
    "shifted_cycle_kernel",
    "shifted_cycle_random_kernel",
    "support",
    "tempering_kernel",
]

#: the starts of the ``C = 3`` chains: thresholded traditional OGM, the all-free map, a draw from the prior
STARTS: tuple[str, ...] = ("ogm", "free", "prior")
#: a cell's chains agree when its split R-hat is below this
RHAT_THRESHOLD = 1.05

Patch = tuple[int, int] | None
#: ``factory(model, patch, init, options) -> kernel``: ``patch`` ``None`` means single cells, ``init`` one of
#: :data:`STARTS`, ``options`` the run's settings (the sampler's own: ``rungs``, ``beta_min``, ``temper``)
KernelFactory = Callable[[OccupancyModel, Patch, str, Any], "MapKernel"]


class ChainOptions(Protocol):
    """What :func:`run_prior_chains` reads of the settings (:class:`~ogm_ppl.calibration.settings.CalibrationSettings`
    has these, and so does any object with the same attributes)."""

    @property
    def sigma(self) -> float: ...
    @property
    def sweeps(self) -> int: ...
    @property
    def burn(self) -> int: ...
    @property
    def seed(self) -> int: ...
    @property
    def kernel(self) -> str: ...
    @property
    def max_support(self) -> int: ...


def gibbs_kernel(model: OccupancyModel, patch: Patch, init: str, options: Any = None) -> MapKernel:
    """Single-cell Gibbs (:class:`~ogm_ppl.inference.CellGibbs`, Section 4.1), or patch Gibbs over ``patch``
    (:class:`~ogm_ppl.inference.PatchGibbs`, Algorithm 2)."""
    return CellGibbs(model, init=init) if patch is None else PatchGibbs(model, patch, init=init)


def tempering_kernel(model: OccupancyModel, patch: Patch, init: str, options: Any) -> MapKernel:
    """Parallel tempering (:class:`~ogm_ppl.inference.mcmc.tempering.ParallelTempering`): ``options.rungs``
    rungs of a geometric ladder ``beta_i = beta_min^{i / (n - 1)}`` down to ``options.beta_min`` on the factor
    ``options.temper`` names, each rung the sampler :func:`gibbs_kernel` would use (cells, or patches of
    ``patch``), even-odd swaps; the cold rung's maps are scored."""
    ladder = geometric_ladder(options.rungs, options.beta_min)
    return ParallelTempering(
        model,
        ladder,
        kernel="cell" if patch is None else "patch",
        patch=patch or (3, 3),
        temper=options.temper,
        init=init,
    )


def cycle_kernel(model: OccupancyModel, patch: Patch, init: str, options: Any = None) -> MapKernel:
    """:func:`~ogm_ppl.inference.mcmc.mixing_cycle`: the ``gibbs`` kernel, then in the same sweep the moves it
    lacks (single cells after tile patches, 2 x 2 patches on two offset tilings after single cells)."""
    return mixing_cycle(model, patch, init=init)


def shifted_cycle_kernel(model: OccupancyModel, patch: Patch, init: str, options: Any = None) -> MapKernel:
    """:func:`~ogm_ppl.inference.mcmc.mixing_cycle` with ``shifted=True`` for tile priors (then patches of the
    tile shape on the tilings shifted by 1 .. min(h, w) - 1 cells, which straddle the tiles); the plain cycle
    for the others."""
    return mixing_cycle(model, patch, init=init, shifted=patch is not None)


def shifted_cycle_random_kernel(model: OccupancyModel, patch: Patch, init: str, options: Any = None) -> MapKernel:
    """As ``shifted-cycle``, with one of the shifted tilings per sweep, drawn at random
    (``mixing_cycle(..., shifted="random")``)."""
    return mixing_cycle(model, patch, init=init, shifted="random" if patch is not None else False)


#: the proposal block of the ``guided`` sampler (a tiling with a random offset at every pass) and the share of its
#: sweeps that are passes of guide moves
GUIDED_BLOCK, GUIDED_P = (6, 6), 0.5


def guided_kernel(model: OccupancyModel, patch: Patch, init: str, options: Any) -> MapKernel:
    """Data-driven MCMC (:class:`~ogm_ppl.inference.mcmc.guided.GuidedGibbs`): each sweep is, with probability
    :data:`GUIDED_P`, a pass of independence Metropolis-Hastings moves proposing :data:`GUIDED_BLOCK` blocks from
    the corpus guide ``options.proposal_guide`` (read from ``options.guide_dir``), else a sweep of the sampler
    :func:`gibbs_kernel` would use; the chain starts at ``init`` (the guide is a proposal, not a start, so the
    three starts test whether its moves carry every chain to the same place). The posterior is stationary."""
    from ogm_ppl.inference.mcmc.guided import GuidedGibbs

    guide = proposal_guide(options.proposal_guide, getattr(options, "guide_dir", None))
    return GuidedGibbs(gibbs_kernel(model, patch, init), guide, block=GUIDED_BLOCK, p_guide=GUIDED_P, init="base")


@lru_cache(maxsize=4)
def proposal_guide(name: str, directory: str | None):
    """The ``guided`` sampler's guide (:func:`~ogm_ppl.calibration.leakage.guide_for`), read once a run."""
    from pathlib import Path

    from ogm_ppl.calibration.leakage import guide_for

    return guide_for(name, None if directory is None else Path(directory))


#: the samplers by name (the ``kernel`` setting); another sampler plugs in by adding an entry
KERNELS: dict[str, KernelFactory] = {
    "gibbs": gibbs_kernel,
    "guided": guided_kernel,
    "tempering": tempering_kernel,
    "cycle": cycle_kernel,
    "shifted-cycle": shifted_cycle_kernel,
    "shifted-cycle-random": shifted_cycle_random_kernel,
}


def default_patch(prior) -> tuple[int, int] | None:
    """The patch a prior is sampled with: its tile (``t_h x t_w``, else 3 x 3) when its compiled bundle
    weighs a sparse support (``sparse_patches()``), ``None`` (single-cell Gibbs) otherwise or for a 1 x 1 tile."""
    c = prior.compiled()
    if c is None or not c.sparse_patches():
        return None
    hw = (int(getattr(c, "t_h", 3)), int(getattr(c, "t_w", 3)))
    return None if hw == (1, 1) else hw


def support(prior, patch: tuple[int, int] | None) -> int:
    """How many configurations one update weighs at most: ``2`` for a single cell, else
    ``min(patch_capacity(L), 2^L)``: the compiled bundle's bound (the largest segment of a sparse tile table,
    which for a border prior counts whole windows) capped by the ``2^L`` configurations ``L`` cells have;
    ``2^L`` without a bundle."""
    if patch is None:
        return 2
    L = int(np.prod(patch))
    c = prior.compiled()
    cap = int(c.patch_capacity(L)) if c is not None else 1 << L
    return min(cap, 1 << L)


def run_prior_chains(
    scene: CalibrationScene,
    name: str,
    options: ChainOptions,
    patch_override: Mapping[str, tuple[int, int] | None] | None = None,
    tables: PriorTables | None = None,
    bias: Mapping[str, float] | None = None,
) -> dict:
    """``C`` chains (:data:`STARTS`) under the prior ``name`` (built from ``tables`` when given, else from the
    shipped corpus; ``NAME+bias`` times ``exp(h sum_k m_k)`` with ``h = bias[NAME]``), each ``options.sweeps``
    sweeps of the ``options.kernel`` sampler after ``options.burn``; ``patch_override`` maps a kind to its
    patch instead of :func:`default_patch`. Returns ``{"marginals": (C, K) array, "rhat": (U,) split R-hat of
    the unseen cells, "seconds_per_chain", "patch"}``, or ``{"skipped": reason}`` when one update would weigh
    more than ``options.max_support`` configurations or a ``@cal`` name has no fitted exponent."""
    name, biased = unbiased_name(name)
    kind, corpus, _, mod = split_prior_name(name)
    if mod == "cal" and tables is None and kind not in load_temper_params(corpus).beta:
        return {"skipped": f"no tempering exponent fitted for {kind} on {corpus} (ogm-ppl fit-prior temper)"}
    prior = prior_by_name(name, scene.grid.shape, tables=tables)
    patch = patch_override[kind] if patch_override and kind in patch_override else default_patch(prior)
    if biased:
        if bias is None or name not in bias:
            raise ValueError(f"{name}+bias: no bias given for {name}")
        prior = BiasedPrior(prior, bias[name])
    n_support = support(prior, patch)
    if n_support > options.max_support:
        return {"skipped": f"a {patch} patch update weighs up to {n_support} configurations (> --max-support)"}
    model = OccupancyModel(scene.grid, scene.rays, GaussianRange(options.sigma), prior)
    unseen = np.flatnonzero(scene.masks["unseen"])
    make = KERNELS[options.kernel]
    marg, traces, secs = [], [], []
    for j, init in enumerate(STARTS):
        t0 = time.perf_counter()
        kernel = make(model, patch, init, options)
        stats = RunningStats(model, trace_cells=unseen)
        run_gibbs(kernel, options.sweeps, stats, warmup=options.burn, seed=options.seed + 1000 * j, progress=False)
        marg.append(stats.marginals.numpy())
        traces.append(stats.trace())
        secs.append(time.perf_counter() - t0)
    rh = split_rhat(np.stack(traces)).numpy() if len(unseen) else np.zeros(0)
    return {
        "marginals": np.stack(marg),
        "rhat": rh,
        "seconds_per_chain": [float(s) for s in secs],
        "patch": None if patch is None else list(patch),
    }


def agreeing(rhat: np.ndarray) -> np.ndarray:
    """Which cells' chains agree: split R-hat below :data:`RHAT_THRESHOLD`; a cell no chain ever changed (R-hat
    NaN: every draw of every chain the same value) agrees."""
    return np.where(np.isnan(rhat), 0.0, rhat) < RHAT_THRESHOLD


def run_prior(
    scene: CalibrationScene,
    name: str,
    options: ChainOptions,
    patch_override: Mapping[str, tuple[int, int] | None] | None = None,
    tables: PriorTables | None = None,
    bias: Mapping[str, float] | None = None,
) -> dict:
    """:func:`run_prior_chains`, scored: the chains' pooled marginals ``q = (1/C) sum_c q^(c)`` on every mask
    (:func:`~ogm_ppl.calibration.scenes.score_marginals`), and the split R-hat of the unseen cells. Returns
    ``{"scores": {mask: ...}, "seconds", "seconds_per_chain", "patch", "rhat_below", "rhat_below_varying",
    "rhat_max", "rhat_cells"}``, or ``{"skipped": reason}``."""
    run = run_prior_chains(scene, name, options, patch_override, tables, bias)
    if "skipped" in run:
        return run
    q = np.clip(run["marginals"].mean(axis=0), 0.0, 1.0)
    rh = run["rhat"]
    agree = agreeing(rh)
    n = len(rh)
    return {
        "scores": score_marginals(scene, q),
        "seconds": float(sum(run["seconds_per_chain"])),
        "seconds_per_chain": run["seconds_per_chain"],
        "patch": run["patch"],
        "rhat_below": float(agree.mean()) if n else float("nan"),
        "rhat_below_varying": float((rh[~np.isnan(rh)] < RHAT_THRESHOLD).mean()) if (~np.isnan(rh)).any() else math.nan,
        "rhat_max": float(np.nanmax(rh)) if np.isfinite(rh).any() else float("nan"),
        "rhat_cells": n,
    }


def run_ogm(scene: CalibrationScene) -> tuple[dict[str, dict], float]:
    """Traditional OGM with the fitted ``p21`` update (:func:`~ogm_ppl.inference.evidence_grid`), scored:
    ``(scores by mask, seconds)``; never-observed cells keep ``q = 0.5`` and count free when thresholded."""
    t0 = time.perf_counter()
    ogm = evidence_grid(scene.rays, delta_by_name("p21"))
    q = ogm.probabilities.numpy()
    return score_marginals(scene, q, unknown=~ogm.observed.numpy()), time.perf_counter() - t0


def run_guide(scene: CalibrationScene, guide: AmortisedGuide, sigma: float) -> dict:
    """The guide's one-pass marginals ``q(m_k = 1 | z)`` (the model's likelihood with range noise ``sigma``
    cells under a uniform prior gives it the rays) scored like a prior's pooled marginals (no chains, so no
    R-hat): ``{"scores": {mask: ...}, "seconds"}``."""
    from ogm_ppl.priors import IndependentPrior

    t0 = time.perf_counter()
    model = OccupancyModel(scene.grid, scene.rays, GaussianRange(sigma), IndependentPrior(0.5, scene.grid.num_cells))
    q = guide.marginals(model).numpy()
    return {"scores": score_marginals(scene, q), "seconds": time.perf_counter() - t0}
