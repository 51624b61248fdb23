r"""The tasks of an experiment: pure functions of (spec entry, seed) that read and write files under the
output folder, so that the same call gives the same files in this process or on any dask worker.

=========  ============================================================== ==================================
task       does                                                           done when (resume)
=========  ============================================================== ==================================
base       simulated: ground-truth map + planned route; a file (log,      ``datasets/_base/B.json``
           bag, ...): its scans read (:mod:`ogm_ppl.inputs`), the
           benchmark map (traditional OGM > thr)
dataset    the readings of one dataset (``save_dataset``) + what it is    ``datasets/D.json``
           scored on (truth, mapped and touched cells: ``D.eval.npz``)
run        one algorithm on one dataset (one chain): marginals            ``tasks/D/A/cN/result.json``
           (npz + PNG); Gibbs checkpoints and F1-against-time records
score      chains averaged; P-R curve, best F1, AUC, touched-only scores  ``maps/D/A.json``
=========  ============================================================== ==================================

Every done-file carries a hash of what the task was asked to do (``task_hash``); a rerun with a changed
entry recomputes. Every file is written atomically. Each task runs with float64 as torch's default type,
one torch thread and its own torch RNG state (:func:`task_env`), so the numbers do not depend on the
process, the worker or what ran before.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import threading
import time
import warnings
from dataclasses import asdict
from pathlib import Path

import numpy as np
import torch

from ogm_ppl.grid import MAX_CELLS
from ogm_ppl.io import atomic_write, atomic_write_text

__all__ = [
    "TASK_VERSION",
    "base_dir",
    "dataset_path",
    "run_algorithm",
    "run_base",
    "run_dataset",
    "run_dir",
    "run_score",
    "score_path",
    "task_env",
    "algorithm_prior_digest",
    "base_source",
    "task_hash",
]

TASK_VERSION = 2  # 2: the sensor model sees walls in the last half cell of the range (sensors._common)
#: how a floor plan of your own becomes a dataset's base (2: the image's top row at the grid's top; the exterior
#: recorded as unknown, outside the "known" mask), in the hash of such a base only
PLAN_BASE_VERSION = 2
_RNG_LOCK = threading.Lock()  # torch's global RNG is per process: one stochastic run at a time per process


# ------------------------------------------------------------------------------------------ helpers
def algorithm_prior_digest(alg) -> str | None:
    """A digest of the prior that ``alg``'s ``prior`` parameter names, built on an 8 x 8 grid (where a spec's
    prior names are checked; 8 cells for a 1D-only kind): its type, tables and weights and its ``log_prob``
    of seeded maps (:func:`~ogm_ppl.inference.mcmc.fingerprint.prior_digest`). Part of a run's hash, so that
    a rerun after the prior changed under the same name (tables of your own counted anew, a registered kind
    edited) recomputes instead of reusing the old result. ``None`` for a method without a prior name, and
    (with a warning) for a prior that cannot be built on those grids."""
    name = alg.params.get("prior")
    if not isinstance(name, str):
        return None
    from ogm_ppl.inference.mcmc.fingerprint import prior_name_digest

    try:
        return prior_name_digest(name)
    except ValueError as e:
        warnings.warn(
            f"algorithm {alg.name!r}: its prior {name!r} could not be built on an 8 x 8 grid to fingerprint it "
            f"({e}); a rerun after that prior changes under its name reuses the old results",
            stacklevel=2,
        )
        return None


def task_hash(*parts) -> str:
    """A short hash of what a task is asked to do (JSON of ``parts`` and :data:`TASK_VERSION`)."""
    text = json.dumps([TASK_VERSION, *parts], sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


@contextlib.contextmanager
def task_env():
    """float64 default dtype, one torch thread, and the caller's torch RNG state restored afterwards."""
    dtype, threads = torch.get_default_dtype(), torch.get_num_threads()
    torch.set_default_dtype(torch.float64)
    torch.set_num_threads(1)
    try:
        with torch.random.fork_rng(devices=[]):
            yield
    finally:
        torch.set_default_dtype(dtype)
        torch.set_num_threads(threads)


def _savez(path: Path, **arrays) -> Path:
    with atomic_write(path) as f:
        np.savez_compressed(f, **arrays)
    return path


def _write_json(path: Path, obj) -> None:
    atomic_write_text(path, json.dumps(obj, indent=1, sort_keys=True, allow_nan=True))


def read_done(path: Path, expected_hash: str | None = None):
    """The done-file at ``path`` if it exists, is readable and (if given) carries ``expected_hash``."""
    try:
        d = json.loads(Path(path).read_text())
    except (FileNotFoundError, json.JSONDecodeError, OSError):
        return None
    if expected_hash is not None and d.get("hash") != expected_hash:
        return None
    return d


def _grid_array(grid) -> np.ndarray:
    return np.array([*grid.shape, grid.resolution, *grid.origin], dtype=float)


def _grid_from(a):
    from ogm_ppl.grid import Grid

    a = np.asarray(a, float)
    return Grid(tuple(int(s) for s in a[:-3]), float(a[-3]), (float(a[-2]), float(a[-1])))


def base_dir(out: Path) -> Path:
    return Path(out) / "datasets" / "_base"


def dataset_path(out: Path, ds) -> Path:
    return Path(out) / "datasets" / f"{ds.name}.npz"


def run_dir(out: Path, ds, alg, chain: int) -> Path:
    return Path(out) / "tasks" / ds.name / alg.name / f"c{chain}"


def score_path(out: Path, ds, alg) -> Path:
    return Path(out) / "maps" / ds.name / f"{alg.name}.json"


def _png(path: Path, probs, grid, title: str, dpi: int) -> None:
    from ogm_ppl.viz import _plt, plot_map

    plt = _plt()
    fig, ax = plt.subplots(figsize=(5, 5))
    plot_map(np.asarray(probs).reshape(grid.shape), grid, ax=ax, title=title)
    try:
        with atomic_write(path) as f:
            fig.savefig(f, format="png", dpi=dpi, bbox_inches="tight")
    finally:
        plt.close(fig)


# ------------------------------------------------------------------------------------------ base
def base_source(ds) -> list:
    """What identifies the file a dataset's base reads, as it is now (the source of the input's
    :func:`~ogm_ppl.inputs.resume_key`: path, size, modification time), in the base task's hash so that a base
    is rebuilt when its log changes; ``[]`` for a simulated scene (its plan's digest is in its parameters)."""
    from ogm_ppl.inputs import get_input_kind, resume_key

    kind = get_input_kind(ds.kind)
    if not kind.reads_file:
        return []
    p = ds.base_params
    return [resume_key(kind, p["path"], kind.parse({**p.get(ds.kind, {}), **p["reader"]}))["source"]]


def run_base(ds, out: str | Path, h: str, max_cells: int = MAX_CELLS) -> dict:
    """Build the shared part of a dataset (see the module docstring); returns its done-record. A log whose
    grid would exceed ``max_cells`` cells is refused (``ValueError`` naming the log and the limit)."""
    from ogm_ppl.datasets.dataset_file import save_dataset
    from ogm_ppl.grid import Grid
    from ogm_ppl.inference import evidence_grid_from_scans
    from ogm_ppl.inputs import get_input_kind, read_input
    from ogm_ppl.models import delta_by_name

    out = Path(out)
    p = ds.base_params
    t0 = time.perf_counter()
    npz = base_dir(out) / f"{ds.base}.npz"
    with task_env():
        if not get_input_kind(ds.kind).reads_file:  # a simulated scene: its truth and route
            from ogm_ppl.inputs.simulated import simulated_route, simulated_scene

            scene_keys = ("map", "size", "border", "map_seed", "plan", "pixel_size", "resolution")
            with warnings.catch_warnings():  # parse_spec read the plan and showed its warnings once
                warnings.filterwarnings("ignore", message=r".*origin yaw .* ignored", category=UserWarning)
                scene = simulated_scene(**{k: p[k] for k in scene_keys if k in p})
            route = simulated_route(scene, poses=p["poses"], max_range_cells=p["max_range_cells"], seed=p["seed"])
            grid = scene.grid
            _savez(npz, grid=_grid_array(grid), truth=scene.truth, known=scene.known, route=route)
            info = {
                "map_kind": scene.map_kind,
                "known_share": float(scene.known.mean()),
                "route_poses": len(route),
                "occupied_share": float(scene.truth.mean()),
            }
        else:
            log = read_input(ds.kind, p["path"], {**p.get(ds.kind, {}), **p["reader"]})
            if p["extent"] is not None:
                x0, y0, w, hgt = p["extent"]
                res = p["resolution"]
                grid = Grid((round(hgt / res), round(w / res)), res, (x0, y0))
            else:
                grid = log.covering_grid(p["resolution"], p["margin"])
            if grid.num_cells > max_cells:
                raise ValueError(
                    f"{p['path']}: the log's grid at {p['resolution']} m a cell is {grid.rows:,} x {grid.cols:,} = "
                    f"{grid.num_cells:,} cells, over the limit of {max_cells:,} ([experiment] max_cells; or set the "
                    "dataset's extent)"
                )
            b = p["benchmark"]
            ev = evidence_grid_from_scans(grid, log.scans, delta_by_name(b["delta"]), prior=b["prior"])
            truth = (ev.probabilities.numpy() > b["threshold"]).reshape(grid.shape)
            mapped = ev.observed.numpy().reshape(grid.shape)
            save_dataset(
                base_dir(out) / f"{ds.base}.scans.npz",
                log.scans,
                grid=grid,
                truth=truth,
                settings={"reader": p["reader"]},
                provenance={"log": p["path"]},
            )
            _savez(npz, grid=_grid_array(grid), truth=truth, mapped=mapped)
            info = {
                "scans": int(log.scans.num_scans),
                "valid_readings": int(log.scans.num_valid),
                "benchmark_occupied": int(truth.sum()),
                "mapped_share": float(mapped.mean()),
                "log_counts": {k: int(v) for k, v in getattr(log.record, "counts", {}).items()},
            }
    rec = {
        "hash": h,
        "base": ds.base,
        "shape": list(grid.shape),
        "seconds": time.perf_counter() - t0,
        **info,
    }
    _write_json(base_dir(out) / f"{ds.base}.json", rec)
    return rec


# ------------------------------------------------------------------------------------------ dataset
def run_dataset(ds, out: str | Path, h: str, _base=None) -> dict:
    """Build one dataset from its base: readings (``save_dataset``) + ``.eval.npz``; returns the record."""
    from ogm_ppl.datasets.dataset_file import load_dataset, save_dataset
    from ogm_ppl.inference import evidence_grid_from_scans
    from ogm_ppl.models import delta_by_name

    out = Path(out)
    p = ds.params
    t0 = time.perf_counter()
    with task_env():
        with np.load(base_dir(out) / f"{ds.base}.npz", allow_pickle=False) as z:
            grid, truth = _grid_from(z["grid"]), z["truth"].astype(bool)
            route = z["route"] if "route" in z.files else None
            mapped = z["mapped"].astype(bool) if "mapped" in z.files else None
            known = z["known"].astype(bool) if "known" in z.files else np.ones_like(truth)
        if route is not None:  # a simulated scene: scanned at its route's stops
            from ogm_ppl.inputs.simulated import simulated_scans

            data = simulated_scans(
                truth,
                grid,
                route,
                beams=p["beams"],
                max_range_cells=p["max_range_cells"],
                sigma_cells=p["sigma_cells"],
                seed=p["seed"],
                pose_fraction=p["pose_fraction"],
                beam_step=p["beam_step"],
            )
            scans = data.scans
        else:
            full = load_dataset(base_dir(out) / f"{ds.base}.scans.npz").scans
            scans = full.subsample(pose_fraction=p["pose_fraction"], beam_step=p["beam_step"])
        touched = evidence_grid_from_scans(grid, scans, delta_by_name("haehnel")).observed.numpy().reshape(grid.shape)
        if mapped is None:  # simulated: the near-mapped mask grows from what this dataset touched
            mapped = touched
        save_dataset(
            dataset_path(out, ds),
            scans,
            grid=grid,
            truth=truth,
            settings={k: v for k, v in p.items() if k != "reader"} | {"reader": p.get("reader")},
            provenance={"experiment_dataset": ds.name, "base": ds.base},
        )
        _savez(
            dataset_path(out, ds).with_suffix(".eval.npz"),
            truth=truth,
            mapped=mapped,
            touched=touched,
            known=known,
        )
    rec = {
        "hash": h,
        "dataset": ds.name,
        "scans": int(scans.num_scans),
        "beams_per_scan": int(scans.beams_per_scan),
        "valid_readings": int(scans.num_valid),
        "cells": int(grid.num_cells),
        "touched_share": float(touched.mean()),
        "truth_occupied_share": float(truth.mean()),
        "seconds": time.perf_counter() - t0,
    }
    _write_json(out / "datasets" / f"{ds.name}.json", rec)
    return rec


def load_eval(out: Path, ds, metrics):
    """``truth``, the scoring ``mask`` and the ``touched`` mask (flat bool) of a dataset."""
    from ogm_ppl.metrics import near_mapped_mask

    with np.load(dataset_path(out, ds).with_suffix(".eval.npz"), allow_pickle=False) as z:
        truth, mapped, touched = (
            z["truth"].astype(bool),
            z["mapped"].astype(bool),
            z["touched"].astype(bool),
        )
        known = z["known"].astype(bool) if "known" in z.files else np.ones_like(truth)
    kind = metrics.mask_for(ds.kind)
    if kind == "near_mapped":
        mask = near_mapped_mask(mapped, metrics.near_mapped_distance)
    elif kind == "known":
        mask = known
    else:
        mask = np.ones_like(truth)
    return truth.ravel(), mask.ravel(), (mask & touched).ravel()


def records_key(metrics, ds) -> dict:
    """What a sampler's records of its running marginals (:func:`_quick_scores` on the dataset's mask) depend on:
    the mask as scored on ``ds`` (``"auto"`` resolved; ``"known"`` is ``"all"`` on a generated map or a log),
    its distance where it is the near-mapped mask, and the thresholds. The other metrics keys only rescore, so
    changing them reruns no chain."""
    mask = metrics.mask_for(ds.kind)
    if mask == "known" and "plan" not in ds.base_params:
        mask = "all"
    key: dict = {"mask": mask, "thresholds": list(metrics.thresholds)}
    if mask == "near_mapped":
        key["near_mapped_distance"] = metrics.near_mapped_distance
    return key


def _quick_scores(q, truth, mask, thresholds) -> dict:
    from ogm_ppl.metrics import best_f1, roc_auc

    f1, thr = best_f1(q, truth, thresholds=np.asarray(thresholds), mask=mask)
    t = truth[mask]
    auc = roc_auc(q, truth, mask=mask) if 0 < t.sum() < t.size else float("nan")
    return {"f1": f1, "threshold": thr, "auc": auc}


# ------------------------------------------------------------------------------------------ run
#: parameter values of the untimed warm-up run (where a method has the parameter)
_WARM_PARAMS = {"sweeps": 2, "burn_in": 0, "chains": 1, "steps": 2, "num_particles": 1, "fit": "none"}
_WARMED: set[str] = set()


def _warm_up(alg, sigma_cells: float, resolution: float) -> None:
    """Run ``alg`` once per process, untimed, on a 24 x 24 room (8 scans of 36 beams) with its parameters cut to
    a few sweeps or steps, so the compiling of its numba kernels (tens of seconds on a cold cache) and their
    loading are not counted in the first task's ``seconds`` nor in its F1-against-time records. A warm-up that
    fails is ignored: the timed run reports the problem."""
    key = json.dumps([spec_entry(alg), sigma_cells], sort_keys=True, default=str)
    if key in _WARMED:
        return
    _WARMED.add(key)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            warm_run(alg, sigma_cells, resolution)
    except Exception:  # the timed run meets (and reports) whatever failed here
        pass


def warm_run(alg, sigma_cells: float, resolution: float):
    """The warm-up run of :func:`_warm_up` (raises what the method raises); returns its :class:`MapResult`."""
    from ogm_ppl.datasets import simulate_scans
    from ogm_ppl.grid import Grid
    from ogm_ppl.methods import MapProblem, RunContext

    method = alg.method
    names = set(method.param_names())
    params = {**alg.params, **{k: v for k, v in _WARM_PARAMS.items() if k in names}}
    grid = Grid((24, 24), resolution)
    room = np.zeros(grid.shape, bool)
    room[[0, -1], :] = room[:, [0, -1]] = True
    room[8:10, 4:14] = True
    k = np.arange(8)
    poses = np.stack([(6 + 2 * k) * resolution, np.full(8, 16 * resolution), np.zeros(8)], axis=1)
    angles = np.linspace(-np.pi, np.pi, 36, endpoint=False)
    scans = simulate_scans(grid, room, poses, angles, 20 * resolution, sigma_cells, 0)
    return method.run(method.parse(params), MapProblem(grid, scans, sigma_cells=sigma_cells), RunContext(seed=0))


def run_algorithm(
    ds,
    alg,
    chain: int,
    seed: int,
    metrics,
    output,
    out: str | Path,
    h: str,
    resume: bool = True,
    stop_after: int | None = None,
    progress: bool = False,
    _deps=None,
) -> dict | None:
    """Run one algorithm (a registered map method, :mod:`ogm_ppl.methods`) on one dataset (one chain);
    writes ``marginals.npz`` (+ ``map.png``) and ``result.json`` under ``tasks/D/A/cN`` and returns the
    result record (the method's details, and the quick scores).

    A sampling method checkpoints into that folder and resumes from it; its F1-against-time records are
    scored on the dataset's mask. ``stop_after`` (tests, and a deliberate pause): stop a sampling run after
    that many sweeps of this call, leaving its checkpoint and no result (returns None); the next call
    resumes it. ``progress``: plain progress lines of a long run, labelled ``DATASET/ALGORITHM/cN``.
    """
    from ogm_ppl.datasets.dataset_file import load_dataset
    from ogm_ppl.methods import MapProblem, RunContext

    out = Path(out)
    folder = run_dir(out, ds, alg, chain)
    folder.mkdir(parents=True, exist_ok=True)
    data = load_dataset(dataset_path(out, ds))
    grid, scans = data.grid, data.scans
    assert grid is not None  # run_dataset saves every dataset with its grid
    truth, mask, _ = load_eval(out, ds, metrics)
    method = alg.method
    problem = MapProblem(grid, scans, sigma_cells=float(ds.params["sigma_cells"]))
    ctx = RunContext(
        seed=seed,
        checkpoint_dir=folder,
        cache_dir=out,
        resume=resume,
        stop_after=stop_after,
        score=lambda q: _quick_scores(q, truth, mask, metrics.thresholds),
        where=f"experiment dataset {ds.name}",
        progress=progress,
        label=f"{ds.name}/{alg.name}/c{chain}",
    )
    with task_env(), _RNG_LOCK if method.stochastic else contextlib.nullcontext():
        _warm_up(alg, float(ds.params["sigma_cells"]), grid.resolution)
        t0 = time.perf_counter()
        result = method.run(alg.method_params(), problem, ctx)
    if not result.complete:
        return None
    # a resumed chain's time includes the sampling of the calls before this one (its checkpoint keeps it)
    seconds = time.perf_counter() - t0 + float(result.details.get("resumed_seconds") or 0.0)
    q = result.probabilities
    assert q is not None
    _savez(folder / "marginals.npz", marginals=q.reshape(grid.shape), format_version=np.int64(1))
    if output.maps:
        _png(folder / "map.png", q, grid, f"{ds.name} / {alg.name} / chain {chain}", output.dpi)
    rec = {
        "hash": h,
        "dataset": ds.name,
        "algorithm": alg.name,
        "chain": chain,
        "seed": seed,
        "seconds": seconds,
        **_quick_scores(q, truth, mask, metrics.thresholds),
        **result.details,
    }
    _write_json(folder / "result.json", rec)
    (folder / "gibbs.npz").unlink(missing_ok=True)  # the result is final: a sampler's checkpoint is spent
    return rec


# ------------------------------------------------------------------------------------------ score
def run_score(ds, alg, metrics, output, out: str | Path, h: str, _deps=None) -> dict:
    """Average the chains' marginals and score them; writes ``maps/D/A.{npz,png,json}``."""
    from ogm_ppl import metrics as M

    out = Path(out)
    qs = []
    for c in range(alg.chains):
        with np.load(run_dir(out, ds, alg, c) / "marginals.npz", allow_pickle=False) as z:
            qs.append(z["marginals"].ravel())
    q = np.mean(np.stack(qs), axis=0) if len(qs) > 1 else qs[0]
    truth, mask, touched = load_eval(out, ds, metrics)
    thr = np.asarray(metrics.thresholds)

    def block(m):
        c = M.precision_recall(q, truth, thresholds=thr, mask=m)
        i = int(np.argmax(c.f1))
        t = truth[m]
        d = {
            "cells": int(m.sum()),
            "occupied": int(t.sum()),
            "best_f1": float(c.f1[i]),
            "threshold": float(c.thresholds[i]),
            "precision": float(c.precision[i]),
            "recall": float(c.recall[i]),
            "saturated": M.saturated_cells(q, m),
            "curve": {
                "thresholds": c.thresholds.tolist(),
                "precision": c.precision.tolist(),
                "recall": c.recall.tolist(),
                "f1": c.f1.tolist(),
                "tp": c.tp.tolist(),
                "fp": c.fp.tolist(),
                "fn": c.fn.tolist(),
            },
        }
        both = 0 < t.sum() < t.size
        if "auc" in metrics.scores:
            d["auc"] = M.roc_auc(q, truth, mask=m) if both else float("nan")
        if "max_precision" in metrics.scores:
            has = c.tp > 0
            d["max_precision"] = float(c.precision[has].max()) if has.any() else float("nan")
        if "nll_bits" in metrics.scores:
            d["nll_bits"] = M.nll_bits(q, truth, m)
        if "brier" in metrics.scores:
            d["brier"] = M.brier_score(q, truth, m)
        if "ece" in metrics.scores:
            d["ece"] = M.expected_calibration_error(q, truth, m)
        return d

    rec = {
        "hash": h,
        "dataset": ds.name,
        "algorithm": alg.name,
        "condition": ds.condition,
        "entry": ds.entry,
        "measurement_fraction": ds.measurement_fraction,
        "chains": alg.chains,
        "mask": block(mask),
    }
    if metrics.touched_only:
        rec["touched"] = block(touched)
    path = score_path(out, ds, alg)
    path.parent.mkdir(parents=True, exist_ok=True)
    from ogm_ppl.datasets.dataset_file import load_dataset

    grid = load_dataset(dataset_path(out, ds)).grid
    assert grid is not None  # run_dataset saves every dataset with its grid
    _savez(path.with_suffix(".npz"), marginals=q.reshape(grid.shape), format_version=np.int64(1))
    if output.maps:
        _png(path.with_suffix(".png"), q, grid, f"{ds.name} / {alg.name}", output.dpi)
    _write_json(path, rec)
    return rec


def spec_entry(obj) -> dict:
    """A spec dataclass as a plain dict (for hashes)."""
    return asdict(obj)
