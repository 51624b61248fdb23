r"""Pattern fields of a corpus or of plans of one's own: the workflow around :mod:`ogm_ppl.priors.learn_field`.

A pattern field (thesis Section 5.2; Felzenszwalb & Oberlin 2014) scores a map by its windows,
``log p~(m) = sum_windows theta[code] (+ sum_pooled windows theta2[code])``, one parameter per symmetry orbit of
the ``w x w`` window codes. The fit (:mod:`ogm_ppl.priors.learn_field`) is

1. a ``2 x 2`` field by maximum pseudo-likelihood, ``max_phi 1/N sum_k log p(m_k | m_-k; phi) -
   backoff_lambda_/2 |phi|^2``, whose :func:`~ogm_ppl.priors.learn_field.backoff_potentials` ``theta0`` centre
2. the ``3 x 3`` field's pseudo-likelihood objective
   ``max_theta 1/N sum_k log p(m_k | m_-k; theta) - lambda_/2 |theta - theta0|^2`` (at two scales the pooled
   grid's parameters have the penalty centred at 0);
3. tempering (:func:`~ogm_ppl.priors.learn_field.fit_tempered`): the power ``beta`` of the field (each
   ``beta`` with a unary bias matched to the training windows' centre-cell occupied share) whose prior
   samples, from the all-free and the all-occupied map alike, come closest to the validation maps' window
   frequencies, ``min_beta |f_val - f_beta|_1`` among the powers whose two starts agree on the occupancy.

The training plans are split in their order: every ``validation_every``-th plan (10 for the shipped fields,
maps 9, 19, ...) is validation, the rest train. :func:`fit_field` fits one and two scales and writes
``field_<name>.npz`` (``w``, ``theta``, ``occupancy``, ``theta2_scale1``, ``theta2_scale2``, ``occupancy2``: the
format of the shipped ``ogm_ppl/fitted/field_<corpus>.npz``, read by
:func:`~ogm_ppl.priors.pattern_field.field_from_file`) and ``field_<name>.json`` (settings, provenance, the
search curves and a sampler check, :func:`sampler_report`). A fit of a corpus takes minutes: after each scale
the state goes to ``field_<name>.checkpoint.json`` in the output folder, and a rerun with the same options
resumes there (the result is the same as an uninterrupted run: every stage is deterministic for ``seed``);
the checkpoint is removed when the files are written.
"""

from __future__ import annotations

import hashlib
import io
import json
import os
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ogm_ppl.learn._fit_common import (
    FitOptionError,
    FitResult,
    PlanPaths,
    TrainingPlans,
    check_float,
    check_int,
    command,
    fit_setup,
    load_training_plans,
    run_provenance,
    validation_split,
)

__all__ = ["FieldSettings", "fit_field", "recheck_field", "sampler_report"]

#: the shipped fields: maps 9, 19, ... are validation
VALIDATION_EVERY = 10


@dataclass(frozen=True)
class FieldSettings:
    """The settings of :func:`fit_field` (defaults: the shipped fits). ``w``/``backoff_w``: window sides of the
    field and of the field its penalty is centred on; ``lambda_``/``backoff_lambda_``: their L2 penalties;
    ``pl_max_iter``: LBFGS iterations of each PL fit; ``betas``: the powers tried; ``bias_steps``,
    ``bias_range``: the bisection of each power's unary bias; ``agree``: how far the two starts' (and the
    target's) occupancies may differ; ``check_size`` x ``check_size`` grids, ``check_chains`` chains and
    ``check_sweeps`` sweeps per power; ``report_sizes``/``report_sweeps``: the final sampler check; ``seed``."""

    w: int = 3
    backoff_w: int = 2
    backoff_lambda_: float = 1e-3
    lambda_: float = 1e-2
    pl_max_iter: int = 200
    betas: tuple[float, ...] = tuple(round(float(b), 3) for b in np.arange(0.3, 0.8001, 0.05))
    bias_steps: int = 5
    bias_range: float = 1.5
    agree: float = 0.1
    check_size: int = 64
    check_chains: int = 4
    check_sweeps: int = 300
    report_sizes: tuple[int, ...] = (64, 128)
    report_sweeps: int = 300
    seed: int = 0

    def checked(self) -> FieldSettings:
        """These settings, each checked (:class:`~ogm_ppl.learn.FitOptionError` names the first out of range)."""
        w = check_int(self.w, "w", 2, 4)
        check_int(self.backoff_w, "backoff_w", 1, w - 1)
        check_float(self.lambda_, "lambda_", 0.0, 1e3)
        check_float(self.backoff_lambda_, "backoff_lambda_", 0.0, 1e3)
        check_int(self.pl_max_iter, "pl_max_iter", 1, 100_000)
        if not self.betas:
            raise FitOptionError("betas", "give at least one power")
        for b in self.betas:
            check_float(b, "betas", 0.0, 10.0)
        check_int(self.bias_steps, "bias_steps", 0, 50)
        check_float(self.bias_range, "bias_range", 0.0, 100.0)
        check_float(self.agree, "agree", 0.0, 1.0)
        check_int(self.check_size, "check_size", 17, 1024)  # the occupancy leaves 8 cells at each edge out
        check_int(self.check_chains, "check_chains", 1, 256)
        check_int(self.check_sweeps, "check_sweeps", 10, 1_000_000)
        if not self.report_sizes:
            raise FitOptionError("report_sizes", "give at least one grid side")
        for s in self.report_sizes:
            check_int(s, "report_sizes", 17, 1024)
        check_int(self.report_sweeps, "report_sweeps", 10, 1_000_000)
        check_int(self.seed, "seed", 0, 2**32 - 1)
        return FieldSettings(**{**asdict(self), "betas": tuple(float(b) for b in self.betas)})

    def record(self) -> dict:
        """The settings as the field's JSON records them, with the recipe in words."""
        d: dict[str, Any] = asdict(self)
        d["betas"], d["report_sizes"] = list(self.betas), list(self.report_sizes)
        d["penalty"] = "lambda_/2 |theta - theta0|^2, theta0 = backoff_potentials(2 x 2 PL field); scale 2 centred at 0"
        d["bias"] = "unary bias matched to the training windows' centre-cell occupied share (bisection)"
        d["stopping"] = (
            "largest beta whose chains from all-free and all-occupied agree on occupancy within `agree`, "
            "their mean within `agree` of the target (smallest mean held-out gap |f_val - f_model|_1 among those)"
        )
        return d


def fit_field(
    source: str | PlanPaths | TrainingPlans,
    out_dir: str | os.PathLike,
    *,
    settings: FieldSettings | None = None,
    limit: int | None = None,
    pixel_size: float | None = None,
    resolution: float = 0.05,
    name: str | None = None,
    validation_every: int = VALIDATION_EVERY,
    resume: bool = True,
    progress: bool = True,
) -> FitResult:
    """Fit the one- and two-scale pattern fields of ``source``'s training plans (module docstring) and write
    ``field_<name>.npz`` and ``field_<name>.json`` into ``out_dir`` (and, while it runs, a checkpoint there).

    Args:
        source, limit, pixel_size, resolution: the training plans, as :func:`~ogm_ppl.learn.fit_tables` takes
            them.
        out_dir: the folder the files go to (created if missing).
        settings: :class:`FieldSettings` (default: the shipped fits').
        name: the files' name part (default the corpus, or ``plans``).
        validation_every: every this-many-th plan is validation (at least 2, at most the number of plans).
        resume: continue from a checkpoint of the same fit in ``out_dir`` (``False``: start afresh).
        progress: print each stage's progress.

    Raises:
        FitOptionError: an option out of range (the message names it and the limit).
    """
    s = (settings or FieldSettings()).checked()
    out, plans, label, every, tr_idx, va_idx = fit_setup(
        source, out_dir, name, validation_every, limit=limit, pixel_size=pixel_size, resolution=resolution
    )
    cmd = command("field", plans, out, _options(s, every, name))

    from ogm_ppl.io import atomic_write_bytes, atomic_write_text
    from ogm_ppl.priors.learn_field import backoff_potentials, field_stats, fit_pl, fit_tempered
    from ogm_ppl.priors.pattern_field import FIELD_FORMAT_VERSION, load_field
    from ogm_ppl.progress import Progress

    t0 = time.perf_counter()
    say = print if progress else (lambda *a, **k: None)
    maps = [_pair(m) for m in plans.maps()]
    train = [maps[i] for i in tr_idx]
    val = [maps[i] for i in va_idx]
    for what, part in (("training", train), ("validation", val)):
        if not any(m[1].sum() for m in part):
            raise FitOptionError("plans", f"the {what} plans hold no known cell")
    tr = field_stats(train, s.w, 2)
    va = field_stats(val, s.w, 2)
    tr_small = field_stats(train, s.backoff_w, 1)
    t_stats = time.perf_counter() - t0
    say(f"{label}: {len(train)} training / {len(val)} validation maps, statistics in {t_stats:.1f} s", flush=True)
    ckpt = out / f"field_{label}.checkpoint.json"
    key = hashlib.sha256(json.dumps([s.record(), plans.source, every], sort_keys=True).encode()).hexdigest()
    state = _read_checkpoint(ckpt, key) if resume else None
    if state is not None:
        say(f"{label}: resuming from {ckpt} ({', '.join(k for k in state['fits'] if k != 'backoff')} done)")
    state = state or {"key": key, "fits": {}, "arrays": {}}
    fits, arrays = state["fits"], state["arrays"]
    lam = tr.win1 @ ((np.arange(len(tr.win1)) >> (s.w * s.w // 2)) & 1) / max(tr.win1.sum(), 1)
    with Progress(
        3, f"fit-prior field {label}", unit="stage", enabled=progress, initial=len(fits) - 1 if fits else 0
    ) as bar:
        theta0 = None
        for scales in (1, 2):
            if f"scales{scales}" in fits:
                continue
            if theta0 is None:
                phi, _, pll_small = fit_pl(tr_small, 1, s.backoff_lambda_, s.pl_max_iter, progress=progress)
                theta0 = backoff_potentials(phi, s.backoff_w, s.w)
                fits["backoff"] = {"w": s.backoff_w, "phi": phi.tolist(), "train_pll": pll_small}
            t1 = time.perf_counter()
            say(f" {label}, {scales} scale(s):", flush=True)
            th, th2, pll = fit_pl(tr, scales, s.lambda_, s.pl_max_iter, theta0=theta0, progress=progress)
            fit = fit_tempered(
                va,
                th,
                th2,
                betas=s.betas,
                occupancy=float(lam),
                bias_steps=s.bias_steps,
                bias_range=s.bias_range,
                size=s.check_size,
                chains=s.check_chains,
                sweeps=s.check_sweeps,
                agree=s.agree,
                seed=s.seed,
                progress=progress,
            )
            fits[f"scales{scales}"] = {
                "train_pll_at_pl": pll,
                "beta": fit.beta,
                "best_heldout_gap": fit.best_gap,
                "search_columns": [
                    "beta",
                    "heldout_gap_mean_of_starts",
                    "occupancy_from_free",
                    "occupancy_from_occupied",
                    "bias",
                ],
                "search": [list(c) for c in fit.curve],
                "occupancy": fit.occupancy,
                "seconds": round(time.perf_counter() - t1, 2),
            }
            if scales == 1:
                arrays["theta"], arrays["occupancy"] = fit.theta.tolist(), fit.occupancy
            else:
                arrays["theta2_scale1"], arrays["theta2_scale2"] = fit.theta.tolist(), np.asarray(fit.theta2).tolist()
                arrays["occupancy2"] = fit.occupancy
            atomic_write_text(ckpt, json.dumps(state) + "\n")
            bar.update(note=f"{scales} scale(s)")
        npz = {"w": np.array(s.w, np.int64), **{k: np.asarray(arrays[k], np.float64) for k in _ARRAY_ORDER}}
        buf = io.BytesIO()
        np.savez(buf, **npz)  # type: ignore[arg-type]
        check = sampler_report(npz, va, sizes=s.report_sizes, sweeps=s.report_sweeps, seed=s.seed, progress=progress)
        bar.update(note="sampler check")
    path = atomic_write_bytes(out / f"field_{label}.npz", buf.getvalue())
    load_field(path)  # what was written must load
    prov = run_provenance(cmd, plans, validation=f"maps with index % {every} == {every - 1}")
    info = {
        "file": path.name,
        "format_version": FIELD_FORMAT_VERSION,
        "sha256": hashlib.sha256(path.read_bytes()).hexdigest(),
        "bytes": path.stat().st_size,
        "seconds_incl_reading": round(time.perf_counter() - t0, 2),
        "statistics_seconds": round(t_stats, 2),
        "settings": {**s.record(), "validation": prov["validation"]},
        "provenance": prov,
        "train_maps": len(train),
        "validation_maps": len(val),
        "train_cells_pl": int(tr.counts1.sum()),
        "validation_cells_pl": int(va.counts1.sum()),
        "window_centre_occupied_share": float(lam),
        "fits": fits,
        "sampler_check": check,
    }
    side = atomic_write_text(out / f"field_{label}.json", json.dumps(info, indent=1) + "\n")
    ckpt.unlink(missing_ok=True)
    say(f"{label}: wrote {path} ({info['seconds_incl_reading']} s)", flush=True)
    summary = {
        k: {"beta": v["beta"], "best_heldout_gap": v["best_heldout_gap"]} for k, v in fits.items() if k != "backoff"
    }
    return FitResult("field", (path, side), prov, summary, info["seconds_incl_reading"])


#: the fitted arrays of a field file beside ``w``, in the order they are written
_ARRAY_ORDER = ("theta", "occupancy", "theta2_scale1", "theta2_scale2", "occupancy2")


def _pair(m: Any) -> tuple[np.ndarray, np.ndarray]:
    """``(occupancy, known)`` of a training map (a generated map: every cell known)."""
    if hasattr(m, "occupancy"):
        return m.occupancy, m.known
    return m, np.ones_like(m)


def _options(s: FieldSettings, every: int, name: str | None) -> list[str]:
    """The command-line options that differ from the defaults."""
    d, opts = FieldSettings(), []
    for flag, mine, default in (
        ("--betas", s.betas, d.betas),
        ("--check-size", s.check_size, d.check_size),
        ("--check-chains", s.check_chains, d.check_chains),
        ("--check-sweeps", s.check_sweeps, d.check_sweeps),
        ("--pl-max-iter", s.pl_max_iter, d.pl_max_iter),
        ("--bias-steps", s.bias_steps, d.bias_steps),
        ("--report-sizes", s.report_sizes, d.report_sizes),
        ("--report-sweeps", s.report_sweeps, d.report_sweeps),
        ("--seed", s.seed, d.seed),
    ):
        if mine != default:
            opts += [flag, *(f"{v:g}" for v in mine)] if isinstance(mine, tuple) else [flag, str(mine)]
    if every != VALIDATION_EVERY:
        opts += ["--validation-every", str(every)]
    return opts + ([] if name is None else ["--name", name])


def _read_checkpoint(path: Path, key: str) -> dict | None:
    """The state of an unfinished fit with the same options, or ``None``."""
    try:
        state = json.loads(path.read_text())
    except (OSError, ValueError):
        return None
    return state if isinstance(state, dict) and state.get("key") == key else None


def sampler_report(
    arrays: dict,
    va: Any,
    *,
    sizes: tuple[int, ...] = (64, 128),
    sweeps: int = 300,
    seed: int = 0,
    progress: bool = True,
) -> dict:
    """What the compiled sampler draws from fitted fields ``arrays`` (``w``, ``theta``, ``theta2_scale1``,
    ``theta2_scale2``): :func:`~ogm_ppl.priors.learn_field.sampler_check` on grids of ``sizes`` from the all-free,
    all-occupied and noise maps (4 chains, ``sweeps`` sweeps, the last 100 read), with the held-out gap to the
    validation maps' statistics ``va``, and their window-centre occupied share."""
    from ogm_ppl.priors.learn_field import sampler_check

    w = int(arrays["w"])
    lam = va.win1 @ ((np.arange(len(va.win1)) >> (w * w // 2)) & 1) / max(va.win1.sum(), 1)
    out: dict = {"validation_window_centre_occupied_share": float(lam)}
    for key, t1, t2 in (
        ("scales1", arrays["theta"], None),
        ("scales2", arrays["theta2_scale1"], arrays["theta2_scale2"]),
    ):
        rows = sampler_check(t1, t2, w, va, sizes=sizes, starts=("free", "occupied", "noise"), sweeps=sweeps, seed=seed)
        out[key] = rows
        if progress:
            print(
                f"  sampler check {key}: "
                + ", ".join(f"{r['size']} {r['start']} occ {r['occupancy']:.3f} gap {r['gap']:.3f}" for r in rows),
                flush=True,
            )
    return out


def recheck_field(corpus: str, out_dir: str | os.PathLike, *, progress: bool = True) -> Path:
    """Recompute :func:`sampler_report` of the fit ``field_<corpus>.npz`` in ``out_dir`` against the corpus's
    validation plans (every :data:`VALIDATION_EVERY`-th training plan) and store it in ``field_<corpus>.json``
    there (atomically); returns that path."""
    from ogm_ppl.io import atomic_write_text
    from ogm_ppl.priors.learn_field import field_stats
    from ogm_ppl.priors.pattern_field import load_field

    out = Path(out_dir)
    path = out / f"field_{corpus}.json"
    info = json.loads(path.read_text())
    d = load_field(out / f"field_{corpus}.npz")
    plans = load_training_plans(corpus)
    _, val = validation_split(len(plans), VALIDATION_EVERY)
    va = field_stats(list(plans.maps(val)), d["w"], 2)
    info["sampler_check"] = sampler_report(d, va, progress=progress)
    return atomic_write_text(path, json.dumps(info, indent=1) + "\n")
