r"""Priors as predictors of what was not seen, and how well calibrated they are (thesis Chapter 5, 5.2.1-5.2.3).

The protocol. On held-out maps of each *test corpus* (``generated``: maps drawn by
:mod:`ogm_ppl.datasets.mapgen` from seeds disjoint from those the shipped ``generated`` tables counted;
``houseexpo``, ``ipa``, ``dungeon``: :func:`~ogm_ppl.datasets.floorplans.heldout_plans`, the buildings of the
real logs left out) we crop a ``window x window`` map (the window holding the most free cells next to a wall),
simulate a sparse stop-and-scan dataset (a few stops, a few beams) and estimate the posterior marginals
``q_k = p(m_k = 1 | z)`` with every prior learned on every *training corpus* (a test x train matrix) by Gibbs
sampling: single-cell Gibbs (Section 4.1) for priors whose compiled bundle weighs dense conditionals, patch
Gibbs over the prior's tile (``L = 9`` for the 3 x 3 tile priors, Algorithm 2) when the bundle weighs a sparse
support (``sparse_patches()``: tile tables leave single-cell moves stuck). A prior whose update would weigh
more than ``--max-support`` configurations (:func:`support`; the 5 x 5 tables of the richer corpora hold up to
2 x 10^5) is skipped and listed. Traditional OGM with the fitted ``p21`` update is the baseline row (never-observed
cells keep ``q = 0.5``).

The priors: every registered kind, and ``KIND@cal`` beside each kind with a fitted tempering exponent (the
prior raised to the power ``beta`` that ``experiments/fit_temper.py`` chose on validation plans of the
training corpus by this protocol's unseen-cell NLL; :mod:`ogm_ppl.priors.named`). ``--diagonal`` scores each
test corpus with the priors learned on it only.

Guides. ``--guides C ...`` adds a ``guide:C`` row per test map: the one-pass marginals of the amortised guide
learned on corpus ``C``'s training plans (:func:`~ogm_ppl.inference.variational.corpus_guide`,
``ogm-ppl train-guide --corpus C``), the posterior predictive with the corpus itself as the prior. It runs on
every test corpus (with ``--diagonal`` too); :func:`load_corpus_guide` refuses a guide whose record is not the
training set of corpus ``C``'s tables, so the leakage check below covers it. ``--guides houseexpo+ipa``
scores the guide learned on both corpora (``ogm-ppl train-guide --corpus houseexpo ipa``), checked against
each; ``--guides houseexpo+ipa@sym`` the same guide with its logits averaged over the 8 turns and flips of the
window (:attr:`~ogm_ppl.inference.variational.AmortisedGuide.symmetrize`).

Scored cells: the near-mapped mask ``N`` (cells within 10 cells of a cell some ray reached, Fig. 6.16b) and its
*unseen* cells ``U`` (cells of ``N`` no ray reached): NLL in bits per cell
``-1/|M| sum_k log2 q_k^{m_k} (1 - q_k)^{1 - m_k}``, ECE and the reliability diagram (10 equal-width bins),
Brier score, ROC AUC, best F1 and occupied-class IoU at 0.5 (never-observed cells counted free, the convention
of learned map-prediction work), plus the seconds each method took.

Agreement of chains. Each prior runs ``C = 3`` chains from different starts: traditional OGM thresholded at the
prior's mean, the all-free map and a draw from the prior (``prior.sample``). The marginals scored are pooled over
the chains, ``q = (1/C) sum_c q^(c)``; split R-hat (:func:`~ogm_ppl.inference.mcmc.diagnostics.split_rhat`) per
unseen cell over the ``C`` chains' kept sweeps gives the share of unseen cells with ``R-hat < 1.05`` (cells that
keep one value in every sweep of every chain agree and count below; ``rhat_below_varying`` leaves them out).

Leakage. A prior is never scored on a map it was learned from: :func:`check_heldout` rebuilds each shipped
table's training set from its recorded provenance (plan names checked against the stored SHA-256; the generated
corpus's seed streams), and refuses a test map that is in it (or shares a building with it), and any plan of a
real-log building, before anything runs.

Kernels. ``--kernel`` names an entry of :data:`KERNELS`: ``factory(model, patch, init, args) -> kernel`` (a
:class:`~ogm_ppl.inference.mcmc.kernel.MapKernel` that :func:`~ogm_ppl.inference.run_gibbs` drives): ``gibbs``
(the default), ``cycle`` (:class:`~ogm_ppl.inference.mcmc.KernelCycle`: each sweep is that Gibbs sweep followed
by the moves it lacks, single cells after tile patches, 2 x 2 patches on two offset tilings after single cells),
``shifted-cycle`` (the same, and for tile priors patches of the tile shape on the tilings shifted across the
prior's: ``mixing_cycle(..., shifted=True)``), ``shifted-cycle-random`` (one of those shifted tilings per sweep,
drawn at random: ``shifted="random"``) or ``tempering``, parallel tempering whose every rung is that
Gibbs sampler (``--rungs``, ``--beta-min``, ``--temper``; the cold rung is scored, so the pooled marginals and
R-hat are the posterior's). Another sampler plugs in by adding an entry.

Biased priors. ``--bias-file bias.json`` (written by ``experiments/prior_occupancy.py --fit-bias``: a bias ``h`` per
prior name, fitted so that the prior fills an empty window as its training corpus is filled, from the training
tables alone) also runs every prior it names as ``NAME+bias``, the prior times ``exp(h sum_k m_k)``
(:class:`~ogm_ppl.priors.BiasedPrior`), beside the prior itself.

Plans of other buildings. ``--plan-files PATH ...`` (ROS map YAMLs, HouseExpo layouts, images with
``--pixel-size``, or folders of them; :mod:`ogm_ppl.datasets.plan_files`, read at 0.05 m a cell) adds one more
test set, labelled ``--plan-set`` (default ``files``), whose usable plans (all, or the first ``--plans``) are
cropped and scored as the corpora's held-out maps are, with every prior of every ``--train`` corpus (no prior was
learned on them, so ``--diagonal`` does not thin them) and every guide (without ``--guides``,
:data:`PLAN_FILES_GUIDE`); without ``--test`` only the plan set runs, and without ``--priors`` then the kinds of
:data:`PLAN_FILES_PRIORS`. A file under the floor-plan corpora's folder, with the bytes of a corpus plan, a near
copy of one, or a layout under a corpus plan's HouseExpo id is refused (:func:`check_plan_files`). A rerun
resumes only if no plan file changed.
``experiments/log_plans.py`` makes such plans of the real logs' buildings.

Outputs under ``--out`` (default ``out/calibration/``): ``calibration.json`` (settings, provenance, one row per
test corpus, train corpus, map, prior and mask, with its reliability diagram), ``calibration_summary.json`` (the
means over maps without the diagrams: what the docs snapshot), ``calibration.md`` (tables),
``reliability_<test>.png`` (one diagram per prior, pooled over maps, unseen cells, bins of 20 cells or more),
``bars_<mask>.png`` (NLL and AUC per test corpus) and ``matrix_unseen.png`` (NLL of every prior and training
corpus on every test corpus). A rerun with the same settings skips the (map, prior) pairs already in the JSON
and computes again those of a prior or guide that changed since (each row records a digest of what it scored:
:func:`name_digest`, the prior's tables and settings, or the guide's weights).

Priors of your own. A kind registered with :func:`~ogm_ppl.priors.register_prior` in a module named in
``$OGM_PPL_METHODS`` (or imported first) is found by name. Named without a corpus (``--priors my_kind``) it
runs once, with the training label ``own`` (learned on plans of your own, which the leakage check cannot know:
keep your test plans out of them); ``my_kind:houseexpo`` passes the HouseExpo tables to its factory as for a
shipped kind.

Measured run times: the default run (2 maps per corpus, every shipped kind and its ``@cal`` beside it x every
shipped corpus, 673 rows, 16 skipped) took 53.5 min wall on 2 Intel Xeon cores that other jobs shared (load
average 2-3); without the ``@cal`` rows (512 rows) it took 23.5 min on 2 AMD EPYC cores under a load of 4-5.
``--quick`` took 15 s once numba had compiled its kernels. Two runs of the default gave identical numbers.

    python experiments/calibration.py --quick        # smoke run, 1 small map per corpus, 3 priors
    python experiments/calibration.py                # the default matrix (see --help for the sizes)
    python experiments/calibration.py --priors patch3 border --train houseexpo --test ipa dungeon
    python experiments/calibration.py --plan-files my_plans/ --pixel-size 0.05 --guides houseexpo+ipa@sym
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from ogm_ppl import GaussianRange, Grid, OccupancyModel, Rays, raycast
from ogm_ppl.calibration.heldout import (  # noqa: F401  (the names this script's users import)
    GENERATED_HELDOUT_SEED,
    PLAN_FILES_GUIDE,
    PLAN_FILES_PRIORS,
    TEST_CORPORA,
    TestMap,
    check_plan_files,
    choose_window,
    generated_seed,
    generated_windows,
    heldout_maps,
    plan_digests,
    plan_file_maps,
    usable_windows,
)
from ogm_ppl.calibration.leakage import (  # noqa: F401
    GUIDE_JOIN,
    GUIDE_PREFIX,
    GUIDE_SYM,
    GuideNameError,
    LeakageError,
    check_heldout,
    guide_corpora,
    guide_for,
    guide_path,
    load_corpus_guide,
    names_digest,
    training_set,
)
from ogm_ppl.datasets.plan_files import PlanFileError
from ogm_ppl.datasets.stop_and_scan import stop_and_scan
from ogm_ppl.inference import CellGibbs, PatchGibbs, RunningStats, evidence_grid, run_gibbs
from ogm_ppl.inference.mcmc import mixing_cycle
from ogm_ppl.inference.mcmc.diagnostics import split_rhat
from ogm_ppl.inference.mcmc.fingerprint import digest, prior_name_digest
from ogm_ppl.inference.mcmc.tempering import TEMPERS, ParallelTempering, geometric_ladder
from ogm_ppl.io import atomic_write_text, writable_folder
from ogm_ppl.metrics import Reliability, near_mapped_mask, prediction_scores, reliability
from ogm_ppl.models import delta_by_name
from ogm_ppl.priors import BiasedPrior
from ogm_ppl.priors.named import PRIOR_KINDS, load_temper_params, prior_by_name, prior_kinds, split_prior_name
from ogm_ppl.priors.tables import available_tables

if TYPE_CHECKING:
    pass

STARTS: tuple[str, ...] = ("ogm", "free", "prior")
METRICS: tuple[str, ...] = ("nll_bits", "ece", "brier", "auc", "best_f1", "iou")
MASKS: tuple[str, ...] = ("unseen", "near")
OGM_LABEL = "traditional OGM (p21)"
#: the training label of a prior kind of one's own named without a corpus (learned on one's own plans)
OWN = "own"
RHAT_THRESHOLD = 1.05
#: settings a resumed run must share with the JSON it extends
RUN_KEYS = (
    "window",
    "generated_shape",
    "poses",
    "beams",
    "range_cells",
    "sigma",
    "sweeps",
    "burn",
    "seed",
    "kernel",
    "rungs",
    "beta_min",
    "temper",
    "patch",
    "bias",
    "plan_digests",
)


def add_plan_file_arguments(ap: argparse.ArgumentParser) -> None:
    """``--plan-files``, ``--plan-set``, ``--pixel-size`` and ``--plan-outside`` (the scripts that score held-out
    maps take plans of other buildings alike; :func:`check_plan_file_arguments`, :func:`plan_set_maps`)."""
    ap.add_argument(
        "--plan-files",
        nargs="+",
        type=Path,
        default=None,
        metavar="PATH",
        help="also score plans of other buildings: ROS map YAMLs, HouseExpo layouts (.json) or images, or folders "
        "of them (ogm_ppl.datasets.plan_files), as one more test set",
    )
    ap.add_argument("--plan-set", default="files", help="the label of the --plan-files test set (default files)")
    ap.add_argument(
        "--pixel-size", type=float, default=None, help="metres per pixel of --plan-files images (a YAML has its own)"
    )
    ap.add_argument(
        "--plan-outside",
        default="occupied",
        choices=("occupied", "unknown"),
        help="a plan file's unknown and exterior cells: occupied and scored, as the corpora's (default), or unknown: "
        "walls to the simulated sensor, never scored (for maps built from logs, whose unknown cells include "
        "rooms nobody entered)",
    )


def check_plan_file_arguments(ap: argparse.ArgumentParser, args: argparse.Namespace) -> None:
    """Refuse (``ap.error``) ``--plans`` below 1, a plan-set label that is not a plain name or is a test corpus's
    name (in any case) or ``none``, and plan-file options without ``--plan-files``."""
    if args.plans is not None and args.plans < 1:
        ap.error("--plans must be at least 1")
    if args.plan_files:
        reserved = {c.lower() for c in TEST_CORPORA} | {"none"}  # "none": the training corpus of OGM's rows
        if args.plan_set.lower() in reserved or not args.plan_set.replace("_", "").replace("-", "").isalnum():
            ap.error(f"--plan-set {args.plan_set!r}: a name of letters, digits, - and _, not a test corpus nor 'none'")
    elif args.pixel_size is not None or args.plan_outside != "occupied":
        ap.error("--pixel-size and --plan-outside apply to --plan-files only")


def plan_set_maps(args: argparse.Namespace, n: int | None) -> list[TestMap]:
    """The first ``n`` usable maps of the ``--plan-files`` test set (``None``: all of them; :func:`plan_file_maps`
    with the options of :func:`add_plan_file_arguments`)."""
    return plan_file_maps(args.plan_files, n, args.window, args.pixel_size, args.plan_set, args.plan_outside)


def run_guide(scene: Scene, guide, args) -> dict:
    """The guide's one-pass marginals ``q(m_k = 1 | z)`` scored like a prior's pooled marginals (no chains, so
    no R-hat)."""
    from ogm_ppl.priors import IndependentPrior

    t0 = time.perf_counter()
    model = OccupancyModel(
        scene.grid, scene.rays, GaussianRange(args.sigma), IndependentPrior(0.5, scene.grid.num_cells)
    )
    q = guide.marginals(model).numpy()
    return {"scores": _scores(scene, q), "seconds": time.perf_counter() - t0}


def default_patch(prior) -> tuple[int, int] | None:
    """The patch a prior is sampled with: its tile (``t_h x t_w``, else 3 x 3) when its compiled bundle
    weighs a sparse support (``sparse_patches()``), ``None`` (single-cell Gibbs) otherwise or for a 1 x 1 tile."""
    c = prior.compiled()
    if c is None or not c.sparse_patches():
        return None
    hw = (int(getattr(c, "t_h", 3)), int(getattr(c, "t_w", 3)))
    return None if hw == (1, 1) else hw


def _gibbs(model, patch, init, args=None):
    return CellGibbs(model, init=init) if patch is None else PatchGibbs(model, patch, init=init)


def _tempering(model, patch, init, args):
    """Parallel tempering (:class:`~ogm_ppl.inference.mcmc.tempering.ParallelTempering`): ``args.rungs`` rungs of
    a geometric ladder down to ``args.beta_min`` on the factor ``args.temper`` names, each rung the sampler
    ``gibbs`` would use (cells, or patches of ``patch``), even-odd swaps; the cold rung's maps are scored."""
    ladder = geometric_ladder(args.rungs, args.beta_min)
    return ParallelTempering(
        model,
        ladder,
        kernel="cell" if patch is None else "patch",
        patch=patch or (3, 3),
        temper=args.temper,
        init=init,
    )


def _cycle(model, patch, init, args=None):
    """:func:`~ogm_ppl.inference.mcmc.mixing_cycle`: the ``gibbs`` kernel, then in the same sweep the moves it
    lacks (single cells after tile patches, 2 x 2 patches on two offset tilings after single cells)."""
    return mixing_cycle(model, patch, init=init)


def _shifted_cycle(model, patch, init, args=None):
    """:func:`~ogm_ppl.inference.mcmc.mixing_cycle` with ``shifted=True`` for tile priors (then patches of the
    tile shape on the tilings shifted by 1 .. min(h, w) - 1 cells, which straddle the tiles); the plain cycle for the
    others."""
    return mixing_cycle(model, patch, init=init, shifted=patch is not None)


def _shifted_cycle_random(model, patch, init, args=None):
    """As ``shifted-cycle``, with one of the shifted tilings per sweep, drawn at random
    (``mixing_cycle(..., shifted="random")``)."""
    return mixing_cycle(model, patch, init=init, shifted="random" if patch is not None else False)


#: ``name -> factory(model, patch, init, args)``; ``patch`` ``None`` means single cells, ``init`` one of
#: :data:`STARTS`, ``args`` the parsed command line (the sampler's own settings)
KERNELS: dict[str, Callable] = {
    "gibbs": _gibbs,
    "tempering": _tempering,
    "cycle": _cycle,
    "shifted-cycle": _shifted_cycle,
    "shifted-cycle-random": _shifted_cycle_random,
}


def _patch_overrides(items: Sequence[str]) -> dict[str, tuple[int, int] | None]:
    out: dict[str, tuple[int, int] | None] = {}
    for it in items:
        kind, _, spec = it.partition("=")
        try:
            if spec in ("1", "1x1"):
                out[kind] = None
            else:
                r, c = (int(v) for v in spec.lower().split("x"))
                out[kind] = (r, c)
        except ValueError:
            raise SystemExit(f"--patch takes KIND=RxC (e.g. border1=3x3) or KIND=1, got {it!r}") from None
    return out


# ------------------------------------------------------------------------------------------- one map
@dataclass
class Scene:
    tmap: TestMap
    grid: Grid
    rays: Rays
    masks: dict[str, np.ndarray]  # K bool each


def make_scene(t: TestMap, args) -> Scene:
    """The sparse dataset of a test map and its scored masks. Cells the map does not know (``~t.known``) are
    walls to the simulated sensor and are never scored (the corpora's maps know every cell)."""
    grid = Grid(t.truth.shape, resolution=t.resolution)
    data = stop_and_scan(
        t.truth | ~t.known,
        grid,
        num_poses=args.poses,
        beams=args.beams,
        max_range_cells=args.range_cells,
        sigma_cells=args.sigma,
        seed=args.seed,
    )
    rays = raycast(grid, data.scans)
    reached = rays.reached().reshape(grid.shape)
    near = near_mapped_mask(reached, 10.0) & t.known
    unseen = near & ~reached
    return Scene(t, grid, rays, {"near": near.ravel(), "unseen": unseen.ravel()})


def _scores(scene: Scene, q: np.ndarray, unknown=None) -> dict[str, dict]:
    truth = scene.tmap.truth.ravel()
    out = {}
    for mask_name in MASKS:
        mask = scene.masks[mask_name]
        s: dict = dict(prediction_scores(q, truth, mask=mask, unknown=unknown))
        s["reliability"] = reliability(q, truth, mask=mask).to_dict()
        out[mask_name] = s
    return out


def run_ogm(scene: Scene) -> tuple[dict[str, dict], float]:
    t0 = time.perf_counter()
    ogm = evidence_grid(scene.rays, delta_by_name("p21"))
    q = ogm.probabilities.numpy()
    return _scores(scene, q, unknown=~ogm.observed.numpy()), time.perf_counter() - t0


def support(prior, patch: tuple[int, int] | None) -> int:
    """How many configurations one update weighs at most: ``2`` for a single cell, else
    ``min(patch_capacity(L), 2^L)``: the compiled bundle's bound (the largest segment of a sparse tile table, which
    for a border prior counts whole windows) capped by the ``2^L`` configurations ``L`` cells have; ``2^L``
    without a bundle."""
    if patch is None:
        return 2
    L = int(np.prod(patch))
    c = prior.compiled()
    cap = int(c.patch_capacity(L)) if c is not None else 1 << L
    return min(cap, 1 << L)


def run_chains(scene: Scene, name: str, args, patch_override=None, tables=None) -> dict:
    """``C`` chains (:data:`STARTS`) under the prior ``name`` (built from ``tables`` when given, else from the
    shipped corpus), each ``args.sweeps`` sweeps of the ``args.kernel`` sampler after ``args.burn``. Returns
    ``{"marginals": (C, K) array, "rhat": (U,) split R-hat of the unseen cells, "seconds_per_chain", "patch"}``,
    or ``{"skipped": reason}`` when one update would weigh more than ``args.max_support`` configurations."""
    name, biased = unbiased_name(name)
    kind, corpus, _, mod = split_prior_name(name)
    if mod == "cal" and tables is None and kind not in load_temper_params(corpus).beta:
        return {"skipped": f"no tempering exponent fitted for {kind} on {corpus} (experiments/fit_temper.py)"}
    prior = prior_by_name(name, scene.grid.shape, tables=tables)
    patch = patch_override[kind] if patch_override and kind in patch_override else default_patch(prior)
    if biased:
        prior = BiasedPrior(prior, args.bias[name])
    n_support = support(prior, patch)
    if n_support > args.max_support:
        return {"skipped": f"a {patch} patch update weighs up to {n_support} configurations (> --max-support)"}
    model = OccupancyModel(scene.grid, scene.rays, GaussianRange(args.sigma), prior)
    unseen = np.flatnonzero(scene.masks["unseen"])
    make = KERNELS[args.kernel]
    marg, traces, secs = [], [], []
    for j, init in enumerate(STARTS):
        t0 = time.perf_counter()
        kernel = make(model, patch, init, args)
        stats = RunningStats(model, trace_cells=unseen)
        run_gibbs(kernel, args.sweeps, stats, warmup=args.burn, seed=args.seed + 1000 * j, progress=False)
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


def run_prior(scene: Scene, name: str, args, patch_override=None, tables=None) -> dict:
    """:func:`run_chains`, scored: the chains' pooled marginals on every mask, and the split R-hat of the unseen
    cells. Returns ``{"scores": {mask: ...}, "seconds", "patch", "rhat_below", "rhat_max", ...}``, or
    ``{"skipped": reason}``."""
    run = run_chains(scene, name, args, patch_override, tables)
    if "skipped" in run:
        return run
    q = np.clip(run["marginals"].mean(axis=0), 0.0, 1.0)
    rh = run["rhat"]
    agree = agreeing(rh)
    n = len(rh)
    return {
        "scores": _scores(scene, q),
        "seconds": float(sum(run["seconds_per_chain"])),
        "seconds_per_chain": run["seconds_per_chain"],
        "patch": run["patch"],
        "rhat_below": float(agree.mean()) if n else float("nan"),
        "rhat_below_varying": float((rh[~np.isnan(rh)] < RHAT_THRESHOLD).mean()) if (~np.isnan(rh)).any() else math.nan,
        "rhat_max": float(np.nanmax(rh)) if np.isfinite(rh).any() else float("nan"),
        "rhat_cells": n,
    }


# ----------------------------------------------------------------------------------------- the matrix
def prior_names(kinds: Sequence[str], train: Sequence[str]) -> list[tuple[str, str | None]]:
    """``(prior name, training corpus)`` pairs: ``KIND:CORPUS`` for every kind and training corpus (a name that
    already holds ``:CORPUS`` is kept), the uniform ``independent`` (trained on nothing) once, and a kind of
    one's own (not shipped) named without a corpus once, trained on :data:`OWN`."""
    out: list[tuple[str, str | None]] = []
    for k in kinds:
        kind, corpus, at, mod = split_prior_name(k)
        if corpus:
            out.append((k, corpus))
            continue
        if kind not in PRIOR_KINDS:
            out.append((k, OWN))
            continue
        if kind == "independent" and not at:
            out.append(("independent", None))
        out += [(f"{kind}:{c}{at}{mod}", c) for c in train]  # a tempering suffix goes after the corpus
    return list(dict.fromkeys(out))


def _row_key(r: dict) -> tuple:
    return (r["test"], r["plan"], r["prior_name"])


def name_digest(name: str, args, guides: dict) -> str:
    """What a row of ``name`` scored, as a short hash: a guide's weights (and whether it is symmetrised); a prior's
    :func:`~ogm_ppl.inference.mcmc.fingerprint.prior_name_digest` (its tables, settings and log-densities: tables
    counted again, refitted weights or exponents change it) and its bias; ``"unfitted"`` for a ``@cal`` name
    without an exponent (skipped when run). Building each prior here also refuses an unknown name before
    anything runs."""
    if name == OGM_LABEL:
        return "ogm"
    if name.startswith(GUIDE_PREFIX):
        g = guides[name[len(GUIDE_PREFIX) :]]
        return digest(*g.net.state_dict().values(), g.symmetrize)
    base, biased = unbiased_name(name)
    kind, corpus, _, mod = split_prior_name(base)
    if mod == "cal" and kind in PRIOR_KINDS and kind not in load_temper_params(corpus).beta:
        return "unfitted"
    return digest(prior_name_digest(base), args.bias.get(base) if biased else None)


def _kind_label(name: str) -> str:
    """The kind of a prior name with its tempering and bias suffixes: ``border_bo:ipa@cal`` -> ``border_bo@cal``,
    ``border1_bo:ipa+bias`` -> ``border1_bo+bias``."""
    name, biased = unbiased_name(name)
    kind, _, at, mod = split_prior_name(name)
    return kind + at + mod + (BIAS_SUFFIX if biased else "")


#: a prior name ending so is the prior times ``exp(h sum_k m_k)``, ``h`` from ``--bias-file``
#: (:class:`~ogm_ppl.priors.BiasedPrior`)
BIAS_SUFFIX = "+bias"
#: the format tag of a bias file (``{"format", "provenance", "settings", "bias": {prior name: h}}``), which
#: ``experiments/prior_occupancy.py --fit-bias`` writes
BIAS_FORMAT = "ogm_ppl.prior_bias"


def unbiased_name(name: str) -> tuple[str, bool]:
    """``(name without BIAS_SUFFIX, whether it had it)``."""
    return (name[: -len(BIAS_SUFFIX)], True) if name.endswith(BIAS_SUFFIX) else (name, False)


def load_bias_file(path: Path | None) -> dict[str, float]:
    """The biases ``{prior name: h}`` of ``experiments/prior_occupancy.py --fit-bias``'s ``bias.json`` (``{}`` for
    no file), validated; errors name the file."""
    if path is None:
        return {}
    try:
        d = json.loads(Path(path).read_text())
    except (OSError, ValueError) as e:
        raise SystemExit(f"{path}: not a bias file ({type(e).__name__}: {e})") from None
    bias = d.get("bias") if isinstance(d, dict) and d.get("format") == BIAS_FORMAT else None
    if not isinstance(bias, dict) or not all(
        isinstance(k, str) and isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
        for k, v in bias.items()
    ):
        raise SystemExit(f"{path}: not a bias file of format {BIAS_FORMAT!r} with finite biases by prior name")
    return {k: float(v) for k, v in bias.items()}


def _rows_for(test, t: TestMap, name, train, kernel, result, name_hash: str) -> list[dict]:
    rows = []
    for mask, s in result["scores"].items():
        row = {
            "test": test,
            "train": train or "none",
            "plan": t.name,
            "prior": "ogm" if name == OGM_LABEL else "guide" if name.startswith(GUIDE_PREFIX) else _kind_label(name),
            "prior_name": name,
            "kernel": kernel,
            "digest": name_hash,
            "mask": mask,
            **{k: v for k, v in s.items()},
            "seconds": result["seconds"],
        }
        for k in ("seconds_per_chain", "patch", "rhat_below", "rhat_below_varying", "rhat_max", "rhat_cells"):
            if k in result:
                row[k] = result[k]
        rows.append(row)
    return rows


def _load_previous(path: Path, settings: dict, fresh: bool) -> tuple[list[dict], list[dict]]:
    """The rows and the runs (provenance and seconds of each earlier call) of ``path``, if it exists and shares
    :data:`RUN_KEYS` with ``settings``."""
    if fresh or not path.is_file():
        return [], []
    try:
        doc = json.loads(path.read_text())
        rows, old = doc["rows"], doc["settings"]
        runs = doc.get("runs", [])
    except (OSError, ValueError, KeyError, TypeError) as e:
        raise SystemExit(f"{path}: not a calibration result ({type(e).__name__}: {e}); use --fresh") from None
    differ = [k for k in RUN_KEYS if old.get(k) != settings.get(k)]
    if differ:
        raise SystemExit(f"{path}: its settings differ in {differ}; rerun with --fresh or another --out")
    return rows, runs


def drop_changed(rows: list[dict], digests: dict[str, str]) -> list[dict]:
    """``rows`` without those of a name in ``digests`` (the names this run scores) whose recorded digest differs
    from the current one (:func:`name_digest`; a row without one too): they are computed again. One line per
    such name says so."""
    keep, changed = [], {}
    for r in rows:
        now = digests.get(r["prior_name"])
        if now is not None and r.get("digest") != now:
            changed[r["prior_name"]] = changed.get(r["prior_name"], 0) + 1
        else:
            keep.append(r)
    for name, n in changed.items():
        print(f"{name}: changed since {n} earlier row(s) were computed; computing them again", flush=True)
    return keep


def _mean(rows, key) -> float:
    v = [r[key] for r in rows if r.get(key) is not None and not (isinstance(r[key], float) and math.isnan(r[key]))]
    return float(np.mean(v)) if v else float("nan")


def summary(rows: list[dict]) -> list[dict]:
    """Means over maps per (test, train, prior name, mask): the tables' and the figures' numbers, with the
    reliability diagram pooled over the maps."""
    groups: dict[tuple, list[dict]] = {}
    for r in rows:
        groups.setdefault((r["test"], r["train"], r["prior_name"], r["mask"]), []).append(r)
    out = []
    for (test, train, name, mask), g in groups.items():
        rel = Reliability.pooled(Reliability.from_dict(r["reliability"]) for r in g)
        out.append(
            {
                "test": test,
                "train": train,
                "prior_name": name,
                "prior": g[0]["prior"],
                "mask": mask,
                "maps": len(g),
                **{k: _mean(g, k) for k in (*METRICS, "seconds", "rhat_below")},
                "ece_pooled": rel.ece,
                "reliability": rel.to_dict(),
            }
        )
    return out


def _fmt(x) -> str:
    return "" if x is None or (isinstance(x, float) and math.isnan(x)) else f"{x:.3f}"


def tables_md(summ: list[dict], settings: dict) -> str:
    tests = list(dict.fromkeys(s["test"] for s in summ))
    lines = [
        "# Priors as predictors of unseen cells: prediction and calibration\n",
        f"Settings: {json.dumps(settings)}\n",
        "Means over the held-out maps. `rhat<1.05`: share of unseen cells whose split R-hat over the chains from "
        "OGM, all-free and prior-draw starts is below 1.05. Per test corpus, the priors learned on it (on a set of "
        "plan files, which no prior was learned on, every prior):\n",
    ]
    for mask in MASKS:
        for test in tests:
            sel = [s for s in summ if s["test"] == test and s["mask"] == mask and _shown(s, test)]
            if not sel:
                continue
            lines += [
                f"\n**{test}**, {mask} cells ({sel[0]['maps']} maps)\n",
                "| method | " + " | ".join(METRICS) + " | rhat<1.05 | seconds |",
                "|---" * (len(METRICS) + 3) + "|",
            ]
            for s in sel:
                vals = " | ".join(_fmt(s[k]) for k in METRICS)
                lines.append(f"| {s['prior_name']} | {vals} | {_fmt(s['rhat_below'])} | {s['seconds']:.1f} |")
    names = [s for s in summ if s["mask"] == "unseen" and s["prior"] != "ogm"]
    kinds = list(dict.fromkeys(s["prior_name"] for s in names))
    lines += [
        "\n**Across corpora**: NLL (bits/cell) / AUC on the unseen cells, prior (rows, with its training corpus) "
        "against the test corpus (columns)\n",
        "| prior | " + " | ".join(tests) + " |",
        "|---" * (len(tests) + 1) + "|",
    ]
    for k in kinds:
        cells = []
        for test in tests:
            hit = [s for s in names if s["prior_name"] == k and s["test"] == test]
            cells.append(f"{_fmt(hit[0]['nll_bits'])} / {_fmt(hit[0]['auc'])}" if hit else "")
        lines.append(f"| {k} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def _shown(s: dict, test: str) -> bool:
    """Whether a summary row goes into ``test``'s own table and figures: the methods learned on that corpus,
    those learned on nothing and priors of one's own (:data:`OWN`); every method on a plan set (``--plan-files``),
    which no prior was learned on."""
    return test not in TEST_CORPORA or s["train"].removesuffix(GUIDE_SYM) in (test, "none", OWN)


def _labels(names: Sequence[str], test: str) -> list[str]:
    """Bar labels: the prior names without ``:<test>``, except where that would make two alike (``independent``,
    the uniform prior, beside ``independent:<test>``, the one learned on the test corpus)."""
    short = [n.replace(f":{test}", "") for n in names]
    return [s if short.count(s) == 1 else n for s, n in zip(short, names)]


def figures(summ: list[dict], out: Path) -> list[Path]:
    """``reliability_<test>.png`` (unseen cells, priors learned on the test corpus and OGM) and
    ``bars_<mask>.png`` (NLL and AUC per test corpus)."""
    from ogm_ppl.viz import _plt, plot_reliability

    plt = _plt()
    paths = []
    tests = list(dict.fromkeys(s["test"] for s in summ))
    for test in tests:
        sel = [s for s in summ if s["test"] == test and s["mask"] == "unseen" and _shown(s, test)]
        if not sel:
            continue
        cols = min(4, len(sel))
        rows = -(-len(sel) // cols)
        fig, axes = plt.subplots(rows, cols, figsize=(3.2 * cols, 3.2 * rows), squeeze=False)
        for ax, s in zip(axes.flat, sel):
            plot_reliability({s["prior_name"]: Reliability.from_dict(s["reliability"])}, ax=ax, min_count=20)
            ax.set_title(s["prior_name"], fontsize=8)
        for ax in list(axes.flat)[len(sel) :]:
            ax.set_visible(False)
        fig.suptitle(f"{test}: reliability on unseen cells ({sel[0]['maps']} maps pooled)", fontsize=10)
        fig.tight_layout()
        p = out / f"reliability_{test}.png"
        fig.savefig(p, dpi=110)
        plt.close(fig)
        paths.append(p)
    for mask in MASKS:
        fig, axes = plt.subplots(2, len(tests), figsize=(3.6 * len(tests), 6), squeeze=False)
        for j, test in enumerate(tests):
            sel = [s for s in summ if s["test"] == test and s["mask"] == mask and _shown(s, test)]
            labels = _labels([s["prior_name"] for s in sel], test)
            for i, key in enumerate(("nll_bits", "auc")):
                ax = axes[i, j]
                ax.bar(range(len(sel)), [s[key] for s in sel], color="C0")
                ax.set_xticks(range(len(sel)), labels, rotation=70, fontsize=7)
                ax.set_ylabel({"nll_bits": "NLL (bits/cell)", "auc": "ROC AUC"}[key], fontsize=8)
                if i == 0:
                    ax.set_title(test, fontsize=9)
        fig.suptitle(f"{mask} cells, priors learned on the test corpus (every prior on plan files)", fontsize=10)
        fig.tight_layout()
        p = out / f"bars_{mask}.png"
        fig.savefig(p, dpi=110)
        plt.close(fig)
        paths.append(p)
    unseen = [s for s in summ if s["mask"] == "unseen" and s["prior"] != "ogm"]
    names = list(dict.fromkeys(s["prior_name"] for s in unseen))
    if names:
        nll = np.full((len(names), len(tests)), np.nan)
        for s in unseen:
            nll[names.index(s["prior_name"]), tests.index(s["test"])] = s["nll_bits"]
        fig, ax = plt.subplots(figsize=(1.4 * len(tests) + 3.5, 0.28 * len(names) + 1.6))
        im = ax.imshow(nll, cmap="viridis_r", aspect="auto")
        mid = (np.nanmin(nll) + np.nanmax(nll)) / 2  # white on the darker half of the colour map
        for (i, j), v in np.ndenumerate(nll):
            if np.isfinite(v):
                ax.text(j, i, f"{v:.2f}", ha="center", va="center", fontsize=6, color="w" if v > mid else "k")
        ax.set_xticks(range(len(tests)), tests, fontsize=8)
        ax.set_yticks(range(len(names)), names, fontsize=6)
        ax.set_xlabel("test corpus")
        fig.colorbar(im, ax=ax, label="NLL on unseen cells (bits/cell)")
        fig.tight_layout()
        p = out / "matrix_unseen.png"
        fig.savefig(p, dpi=110, bbox_inches="tight")  # long prior names and the colour bar's label kept whole
        plt.close(fig)
        paths.append(p)
    return paths


def parse_args(argv=None) -> argparse.Namespace:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument(
        "--test",
        nargs="+",
        default=None,
        choices=TEST_CORPORA,
        help="test corpora (default: all of them, or none where --plan-files is given)",
    )
    add_plan_file_arguments(ap)
    ap.add_argument("--train", nargs="+", default=None, help="training corpora of the tables (default: all shipped)")
    ap.add_argument(
        "--priors",
        nargs="+",
        default=None,
        help="prior kinds or names (default: every kind, and KIND@cal where fitted; with --plan-files alone, "
        f"{' '.join(PLAN_FILES_PRIORS)})",
    )
    ap.add_argument(
        "--guides",
        nargs="*",
        default=None,
        help="also score the amortised guide learned on each of these corpora (guide:CORPUS rows; "
        "ogm-ppl train-guide); CORPUS@sym: the guide symmetrised (default: none, or with "
        f"--plan-files the floor-plan guide {PLAN_FILES_GUIDE})",
    )
    ap.add_argument(
        "--guide-dir",
        default=None,
        help="read the --guides as DIR/guide_CORPUS.npz (default: the shipped ones in ogm_ppl/fitted); their "
        "records are checked against the tables' training sets all the same",
    )
    ap.add_argument(
        "--diagonal",
        action="store_true",
        help="score each test corpus only with the priors learned on it (every guide still runs on every corpus)",
    )
    ap.add_argument(
        "--plans", type=int, default=None, help="held-out maps per test corpus (default 2; every plan of --plan-files)"
    )
    ap.add_argument("--window", type=int, default=96, help="maps are cropped to this many cells a side")
    ap.add_argument("--generated-shape", type=int, default=160, help="side of the held-out generated maps")
    ap.add_argument("--poses", type=int, default=3, help="stops of the sparse route")
    ap.add_argument("--beams", type=int, default=90, help="beams per 360-degree scan")
    ap.add_argument("--range-cells", type=float, default=75.0)
    ap.add_argument("--sigma", type=float, default=1.0, help="range noise, cells")
    ap.add_argument("--sweeps", type=int, default=200, help="kept sweeps per chain")
    ap.add_argument("--burn", type=int, default=50, help="warm-up sweeps per chain")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--kernel", default="gibbs", choices=sorted(KERNELS), help="sampler (an entry of KERNELS)")
    ap.add_argument("--rungs", type=int, default=6, help="tempering: rungs of the geometric ladder (cold one included)")
    ap.add_argument("--beta-min", type=float, default=0.1, help="tempering: the hottest rung's exponent, in (0, 1)")
    ap.add_argument("--temper", default="prior", choices=TEMPERS, help="tempering: the factor the ladder raises")
    ap.add_argument("--patch", nargs="*", default=[], help="per-kind patch override: KIND=RxC or KIND=1")
    ap.add_argument(
        "--bias-file",
        type=Path,
        default=None,
        help="bias.json of prior_occupancy.py --fit-bias: each prior it names also runs biased (NAME+bias)",
    )
    ap.add_argument(
        "--max-support",
        type=int,
        default=4096,
        help="skip a prior whose patch update weighs more configurations than this (5 x 5 tables)",
    )
    ap.add_argument("--out", default="out/calibration")
    ap.add_argument("--fresh", action="store_true", help="ignore rows already in the output JSON")
    ap.add_argument("--no-figures", action="store_true")
    ap.add_argument("--quick", action="store_true", help="smoke run: 1 map of 48 cells per corpus, 3 priors")
    args = ap.parse_args(argv)
    if args.sweeps < 4 or args.burn < 0:
        ap.error("--sweeps must be at least 4 (split R-hat halves each chain) and --burn at least 0")
    if args.kernel == "tempering":
        try:
            geometric_ladder(args.rungs, args.beta_min)
        except ValueError as e:
            ap.error(f"--rungs / --beta-min: {e}")
    if args.quick:
        args.plans, args.window, args.sweeps, args.burn = 1, 48, 40, 10
        args.generated_shape = 96
        args.priors = args.priors or ["independent", "mrf", "border"]
        args.train = args.train or ["houseexpo"]
    args.train = args.train or available_tables()
    if args.test is None:
        args.test = [] if args.plan_files else list(TEST_CORPORA)
    if args.priors is None:  # plan files alone: the priors of the results page's buildings in no corpus
        args.priors = list(PLAN_FILES_PRIORS) if args.plan_files and not args.test else default_priors(args.train)
    if args.guides is None:  # a building in no corpus: the guide the docs recommend for one runs by default
        args.guides = [PLAN_FILES_GUIDE] if args.plan_files else []
    check_plan_file_arguments(ap, args)
    args.plan_limit = args.plans  # None: every plan of --plan-files
    if args.plans is None:
        args.plans = 2
    return args


def default_priors(train: Sequence[str]) -> list[str]:
    """Every registered kind, then ``KIND@cal`` for each kind with a fitted tempering exponent on every
    training corpus (:func:`~ogm_ppl.priors.named.load_temper_params`)."""
    kinds = list(prior_kinds())
    fitted = None
    for c in train:
        try:
            have = set(load_temper_params(c).beta)
        except FileNotFoundError:
            have = set()
        fitted = have if fitted is None else fitted & have
    return kinds + [f"{k}@cal" for k in kinds if k in (fitted or set())]


def main(argv=None) -> dict:
    from benchmarks._common import provenance

    args = parse_args(argv)
    torch.set_num_threads(1)
    out = Path(args.out)
    path = out / "calibration.json"
    own = () if args.kernel == "tempering" else ("rungs", "beta_min", "temper")  # only the sampler's own settings
    args.bias = load_bias_file(args.bias_file)
    settings = {k: v for k, v in vars(args).items() if k not in ("out", "fresh", "no_figures", "bias_file", *own)}
    if not args.bias:  # settings without biases read as those of runs made before --bias-file existed
        del settings["bias"]
    if args.plan_files:
        if not args.test:  # "plans" counts the corpora's maps; plan_limit the plan set's (None: all)
            del settings["plans"]
        settings["plan_files"] = [str(p) for p in args.plan_files]
        try:
            settings["plan_digests"] = plan_digests(args.plan_files)  # a changed plan file refuses to resume
        except PlanFileError as e:
            raise SystemExit(f"calibration.py: {e}") from None
    else:  # likewise for runs made before --plan-files existed
        for k in ("plan_files", "plan_set", "pixel_size", "plan_outside", "plan_limit"):
            del settings[k]
    overrides = _patch_overrides(args.patch)
    pairs = prior_names(args.priors, args.train)
    pairs += [(n + BIAS_SUFFIX, c) for n, c in pairs if n in args.bias]  # each biased prior beside its base
    try:
        guides = {c: guide_for(c, args.guide_dir) for c in args.guides}
    except GuideNameError as e:
        raise SystemExit(f"--guides: {e}") from None
    pairs += [(GUIDE_PREFIX + c, c) for c in args.guides]
    try:  # builds every prior once: an unknown name or unreadable tables stop the run before any work
        digests = {name: name_digest(name, args, guides) for name, _ in [(OGM_LABEL, None), *pairs]}
    except (ValueError, LookupError, OSError) as e:
        raise SystemExit(f"calibration.py: {e}") from None
    try:  # after the names: a refused run leaves no folder behind
        writable_folder(out)
    except OSError as e:
        raise SystemExit(f"calibration.py: --out {e}") from None
    rows, runs = _load_previous(path, settings, args.fresh)
    rows = drop_changed(rows, digests)
    done = {_row_key(r) for r in rows}
    skipped: list[dict] = []
    skipped_keys: set[tuple] = set()
    prov = provenance()
    t_all = time.perf_counter()

    def save():
        doc = {
            "provenance": prov,
            "settings": settings,
            "rows": rows,
            "skipped": skipped,
            "runs": [*runs, {"provenance": prov, "seconds": time.perf_counter() - t_all}],
            "seconds": sum(r["seconds"] for r in runs) + time.perf_counter() - t_all,
        }
        atomic_write_text(path, json.dumps(doc, indent=1))

    test_sets = [(test, heldout_maps(test, args.plans, args.window, args.generated_shape)) for test in args.test]
    if args.plan_files:
        try:
            test_sets.append((args.plan_set, plan_set_maps(args, args.plan_limit)))
        except (PlanFileError, LeakageError) as e:
            raise SystemExit(f"calibration.py: {e}") from None
    runs_of = {}
    for test, maps in test_sets:  # refuse leakage before anything runs
        own = test in TEST_CORPORA and args.diagonal  # a plan set has no priors of its own: every one runs on it
        runs_of[test] = [(n, c) for n, c in pairs if not own or n.startswith(GUIDE_PREFIX) or c in (None, OWN, test)]
        for name, train in runs_of[test]:
            for c in guide_corpora(train) if name.startswith(GUIDE_PREFIX) else [train]:
                check_heldout(test, [t.plan for t in maps], c)
    for test, maps in test_sets:
        pairs_here = runs_of[test]
        print(
            f"[{test}] {len(maps)} held-out maps: " + ", ".join(f"{t.name} {t.truth.shape}" for t in maps), flush=True
        )
        for t in maps:
            scene = None
            todo = [(OGM_LABEL, None)] + pairs_here
            for name, train in todo:
                if (test, t.name, name) in done:
                    continue
                scene = scene or make_scene(t, args)
                if name == OGM_LABEL:
                    scores, secs = run_ogm(scene)
                    result: dict = {"scores": scores, "seconds": secs}
                elif name.startswith(GUIDE_PREFIX):
                    result = run_guide(scene, guides[train], args)
                else:
                    result = run_prior(scene, name, args, overrides)
                    if "skipped" in result:
                        if (test, t.name, name) not in skipped_keys:
                            skipped.append({"test": test, "plan": t.name, "prior_name": name, **result})
                            skipped_keys.add((test, t.name, name))
                        print(f"  {test} {t.name[:28]}: {name:<22} skipped: {result['skipped']}", flush=True)
                        continue
                rows += _rows_for(test, t, name, train, args.kernel, result, digests[name])
                done.add((test, t.name, name))
                u = result["scores"]["unseen"]
                rh = f", rhat<1.05 {result['rhat_below']:.2f}" if "rhat_below" in result else ""
                print(
                    f"  {test} {t.name[:28]}: {name:<22} NLL {u['nll_bits']:.3f} AUC {_fmt(u['auc'])} "
                    f"ECE {u['ece']:.3f}{rh} ({result['seconds']:.1f} s, {time.perf_counter() - t_all:.0f} s in all)",
                    flush=True,
                )
                save()
    save()
    summ = summary(rows)
    brief = [{k: v for k, v in r.items() if k != "reliability"} for r in summ]
    atomic_write_text(
        out / "calibration_summary.json",
        json.dumps(
            {"provenance": prov, "settings": settings, "summary": brief, "skipped": skipped}, separators=(",", ":")
        ),
    )
    md = tables_md(summ, settings)
    atomic_write_text(out / "calibration.md", md)
    figs = [] if args.no_figures else figures(summ, out)
    print(md)
    print(f"wrote {path}, {out / 'calibration.md'}" + (f" and {len(figs)} figures" if figs else ""), flush=True)
    return {"rows": rows, "summary": summ, "path": path}


if __name__ == "__main__":
    main()
