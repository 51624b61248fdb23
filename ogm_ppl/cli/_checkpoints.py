"""Checkpoints of ``ogm-ppl map``'s chains (``OUT/.checkpoints``, keyed by what the chain depends on) and the
online map (``--online``: scans added one at a time to a running chain)."""

from __future__ import annotations

import dataclasses
import json
import shutil
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ogm_ppl.grid import Grid
from ogm_ppl.methods import (
    MapProblem,
)

if TYPE_CHECKING:
    from ogm_ppl.methods import MapMethod
from ogm_ppl.cli._common import (
    CLIError,
    _jsonable,
)
from ogm_ppl.cli._input import (
    _Input,
)

CHECKPOINTS = ".checkpoints"


def _prior_digest(params) -> str | None:
    """:func:`~ogm_ppl.inference.mcmc.fingerprint.prior_name_digest` of the prior ``params`` names (what its
    tables, weights and settings are now); ``None`` without a prior name, or for one that builds only on the
    map's own grid (the run says what is wrong with it)."""
    from ogm_ppl.inference.mcmc.fingerprint import prior_name_digest

    name = getattr(params, "prior", None)
    if not isinstance(name, str):
        return None
    try:
        return prior_name_digest(name)
    except ValueError:
        return None


def _checkpoint_root(args, params, inp: _Input, grid: Grid) -> Path | None:
    """``DIR/.checkpoints/METHOD-KEY`` for a sampling method (``None`` for the others): ``KEY`` digests the
    command's settings, the prior's content (:func:`_prior_digest`), the input's resume key
    (:func:`ogm_ppl.inputs.resume_key`: its kind, the file's size and modification time, the reader's options)
    and the grid, so that only the same command on the same input under the same prior resumes a chain
    (each chain in ``chain-C``; its checkpoint's fingerprint checks the model too,
    :func:`~ogm_ppl.inference.mcmc.run_gibbs`)."""
    import hashlib

    from ogm_ppl.methods._sampling import SamplingParams

    if not isinstance(params, SamplingParams) or getattr(args, "online", False):
        return None
    ignore = ("out", "traceback", "input", "unobserved", "thresholds")  # how the map is written, not computed
    key = {
        "settings": _jsonable({k: v for k, v in sorted(vars(args).items()) if k not in ignore}),
        "params": _jsonable(dataclasses.asdict(params)),
        "prior": _prior_digest(params),
        "input": inp.resume_key,
        "grid": [grid.rows, grid.cols, grid.resolution, *grid.origin],
    }
    digest = hashlib.sha256(json.dumps(key, sort_keys=True).encode()).hexdigest()[:16]
    return args.out / CHECKPOINTS / f"{args.method}-{digest}"


def _online_map(
    args, method: MapMethod, params, problem: MapProblem, times: dict
) -> tuple[np.ndarray, np.ndarray, dict]:
    """``--online``: the scans replayed one at a time into :class:`~ogm_ppl.inference.online.OnlineMap`
    (:func:`~ogm_ppl.inference.online.replay`); the snapshots ride in ``details["_snapshots"]``."""
    from ogm_ppl.inference.online import replay

    if method.name == "amortised":
        return _online_guide_map(args, params, problem, times)
    if method.name != "gibbs" or params.patch != 1 or params.chains != 1 or params.update == "thesis":
        raise CLIError(
            "--online runs one single-cell Gibbs chain (--method gibbs: patch 1, one chain) or keeps the amortised "
            "guide's map (--method amortised)"
        )
    if params.threads is not None:
        raise CLIError("--online sweeps around each new scan serially: drop --threads")
    # the offline chain's start, kept as the scans arrive: reached cells restart from thresholded OGM
    init_new = {"ogm": "ogm", "free": "keep"}.get(params.init)
    if init_new is None or (params.init == "ogm" and params.init_delta != "haehnel"):
        raise CLIError(
            f"--online starts from thresholded traditional OGM (init=ogm, init_delta=haehnel) or all free "
            f"(init=free), got init={params.init!r}, init_delta={params.init_delta!r}"
        )
    sensor = problem.sensor(params.sensor, params.sigma_cells, params.p_rand)
    t0 = time.perf_counter()
    r = replay(
        problem.grid,
        problem.scans,
        sensor,
        problem.prior(params.prior, params.lam),
        burn_in=params.burn_in,
        sweeps=params.sweeps,
        snapshot_every=args.snapshots,
        progress=True,  # a bar on a terminal, plain lines in a log once past 10 s
        seed=args.seed,
        update=params.update,
        init_new=init_new,
    )
    times["ray_cast_s"], times["map_s"] = None, time.perf_counter() - t0
    om = r.online
    details = {
        **dataclasses.asdict(params),
        "sigma_cells": problem.sigma(params.sigma_cells),  # the noise the sensor model was built with
        "sensor_model": repr(sensor),
        "kernel": "OnlineMap",
        "seed": args.seed,
        "online": {
            "scans": om.num_scans,
            "sweeps_per_scan": om.sweeps_per_scan,
            "full_every": om.full_every,
            "margin": om.margin,
            "init_new": om.init_new,
            "sweeps_total": om.sweeps_done,
            "full_sweeps": om.full_sweeps,
            "mean_seconds_per_scan": float(r.seconds_per_scan.mean()),
        },
        "_snapshots": r.snapshots,
    }
    return r.probabilities, r.observed, details


def _online_guide_map(args, params, problem: MapProblem, times: dict) -> tuple[np.ndarray, np.ndarray, dict]:
    """``--online --method amortised``: the scans replayed one at a time into
    :class:`~ogm_ppl.inference.online.OnlineGuideMap` (:func:`~ogm_ppl.inference.online.replay_guide`), the guide's
    setting checked on the first scan's rays; the final map is the guide's map of every scan to float32 rounding."""
    from ogm_ppl.inference.online import replay_guide
    from ogm_ppl.inference.online._replay import _one
    from ogm_ppl.methods.amortised import load_guide, set_symmetrize
    from ogm_ppl.models.occupancy import OccupancyModel
    from ogm_ppl.priors import IndependentPrior
    from ogm_ppl.raycast import raycast

    scans, grid = problem.scans, problem.grid
    assert scans.valid is not None  # Scans.__post_init__ always sets the S x B mask
    first = _one(scans, int(np.flatnonzero(scans.valid.any(1))[0]))
    model = OccupancyModel(grid, raycast(grid, first), problem.sensor(), IndependentPrior(0.5, grid.num_cells))
    guide = load_guide(params.guide, model, noise_known=problem.sigma_cells is not None)
    set_symmetrize(guide, params.symmetrize)  # refused by its name before the replay
    t0 = time.perf_counter()
    r = replay_guide(grid, scans, guide, symmetrize=params.symmetrize, snapshot_every=args.snapshots, progress=True)
    times["ray_cast_s"], times["map_s"] = None, time.perf_counter() - t0
    s = r.seconds_per_scan[r.seconds_per_scan > 0]
    details = {
        **dataclasses.asdict(params),
        "trained_for": guide.trained_for,
        "kernel": "OnlineGuideMap",
        "online": {
            "scans": r.online.num_scans,
            "symmetrize": r.online.symmetrize,
            "mean_seconds_per_scan": float(s.mean()) if s.size else 0.0,
            "median_seconds_per_scan": float(np.median(s)) if s.size else 0.0,
        },
        "_snapshots": r.snapshots,
    }
    return r.probabilities, r.observed, details


def _drop_own_checkpoints(args, own: Path | None) -> None:
    """The map is written: its chains' checkpoints are spent. Those of other commands run into the same folder
    (other settings or input, interrupted) stay, and a note says where they are."""
    root = args.out / CHECKPOINTS
    if own is not None:
        shutil.rmtree(own, ignore_errors=True)
    try:
        others = sorted(p.name for p in root.iterdir())
    except OSError:
        return
    if not others:
        root.rmdir()
        return
    print(
        f"ogm-ppl map: {root} keeps the checkpoints of {len(others)} other interrupted run(s) ({', '.join(others)}): "
        "rerunning their command resumes them; delete the folder to drop them",
        file=sys.stderr,
    )
