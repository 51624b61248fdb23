r"""Tempering exponents of the learned priors, chosen on validation plans: the ``@cal`` of :mod:`ogm_ppl.priors.named`.

A prior learned by counting (the MRF's ``psi``, the tile tables, their backed-off forms; thesis Chapter 5) is
fitted to whole maps, not to what it must do in mapping: predict the cells no ray reached. Tables whose
configurations are near-deterministic given their border freeze the sampler into confident guesses, and a
confident mistake costs many bits. Raising the prior to a power ``beta <= 1``
(:class:`~ogm_ppl.priors.TemperedPrior`, ``p~(m)^beta``) weakens its coupling; ``beta`` is chosen on training
data only, by the quantity the calibration protocol scores (Section 5.2.1):

.. math::

    \hat\beta = \arg\min_{\beta \in B} \frac{1}{P} \sum_{p=1}^{P} \Big( -\frac{1}{|U_p|}
        \sum_{k \in U_p} \log_2 q_{\beta,k}^{m_k} (1 - q_{\beta,k})^{1 - m_k} \Big),

``q_beta`` the pooled marginals of ``C = 3`` chains (thresholded OGM, all-free and prior-draw starts;
:func:`~ogm_ppl.calibration.run_prior`) under ``KIND:CORPUS@beta`` on a sparse simulated scan of validation
plan ``p`` (:func:`~ogm_ppl.calibration.make_scene`), ``U_p`` its unseen near-mapped cells; ties go to the
larger ``beta``.

The split is :func:`~ogm_ppl.learn.fit_backoff`'s (every fifth training plan is validation, of the random
``sample`` of them where the shipped tables counted one; the backed-off kinds use the shipped ``kappa``, chosen
on this split); every table is counted on the fit part only. The first
``plans`` validation plans with at least 200 free cells in their window are scored. For ``generated`` (no plan
names) the validation maps are fresh draws of the generator from a seed stream no table and no held-out map
uses (:data:`VALIDATION_SEED`), with the shipped tables.

**A net field** (``--kinds net``, a kind fitted as a file: :data:`~ogm_ppl.priors.named.FILE_KINDS`) counts no
tables: its exponent is scored on windows of the plans the net's own fit kept for validation
(:func:`~ogm_ppl.learn._heldout.file_kind_validation`: every tenth of the same training plans, which it never
trained on), and its entry records, at each exponent, the statistics of its prior samples (occupied share and
mean runs from the all-free and the all-occupied start, their gap showing an ordered phase) beside the
validation plans' (:func:`~ogm_ppl.learn._heldout.file_kind_record`). ``net:CORPUS@cal`` then reads it.

:func:`fit_temper` writes ``temper_<corpus>.json`` (``beta`` per kind, every ``(beta, kind)`` score per plan,
the settings and provenance), read by :func:`~ogm_ppl.priors.named.load_temper_params`
(``ogm-ppl fit-prior temper --corpus C --out DIR``; ``--ship`` replaces the package's
``ogm_ppl/fitted/temper_<corpus>.json``).
"""

from __future__ import annotations

import json
import os
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ogm_ppl.learn._fit_common import CORPORA, FitOptionError, FitResult, check_float, check_int
from ogm_ppl.learn._heldout import (
    FILE_KINDS,
    count_fit_tables,
    file_kind_path,
    file_kind_record,
    file_kind_validation,
    names_sha256,
    output_folder,
    shell_command,
    split_names,
    validation_windows,
)

__all__ = ["BETAS", "KINDS", "VALIDATION_SEED", "TemperSettings", "choose", "fit_temper"]

#: the kinds built from counted tables (the fields fit their own exponent on their own split)
KINDS: tuple[str, ...] = ("mrf", "mrf8", "patch3", "border", "border1", "patch3_bo", "border_bo", "border1_bo")
#: the exponents tried
BETAS: tuple[float, ...] = (1.0, 0.75, 0.5, 0.35, 0.25, 0.15, 0.1, 0.05)
#: validation generated map ``i`` is ``generate_map(KINDS[i % 4], seed=VALIDATION_SEED + i)``: a root seed
#: stream apart from the tables' spawned children and from the held-out maps' (calibration, 50_000 + i)
VALIDATION_SEED = 70_000
#: the settings that define the protocol (an update keeps the other kinds only when these agree)
_PROTOCOL = (
    "plans",
    "window",
    "generated_shape",
    "poses",
    "beams",
    "range_cells",
    "sigma",
    "sweeps",
    "burn",
    "seed",
    "max_support",
    "kernel",
)
_KERNELS = ("gibbs", "cycle", "shifted-cycle", "shifted-cycle-random")


@dataclass(frozen=True)
class TemperSettings:
    """The settings of :func:`fit_temper` (defaults: the shipped fits but for ``betas``). ``kinds`` and
    ``betas``: what is tried; ``plans`` validation plans of ``window`` cells a side (``generated_shape``: the
    generated maps' side); the scan: ``poses`` stops, ``beams`` beams, ``range_cells``, range noise ``sigma``
    cells; the chains: ``sweeps`` kept after ``burn``, the ``kernel`` (:data:`~ogm_ppl.calibration.KERNELS`),
    updates weighing more than ``max_support`` configurations skip the kind; ``seed``; ``fit_limit``: count
    the tables on the first ``fit_limit`` fit plans only (a quick run; ``None``: all); ``sample``: split a random
    ``sample`` of a floor-plan corpus's training plans (``sample_seed``; the one its shipped tables were
    counted on, e.g. ``houseexpo-full``'s ``--sample 1000``) instead of all of them."""

    kinds: tuple[str, ...] = KINDS
    betas: tuple[float, ...] = BETAS
    plans: int = 3
    window: int = 96
    generated_shape: int = 160
    poses: int = 3
    beams: int = 90
    range_cells: float = 75.0
    sigma: float = 1.0
    sweeps: int = 100
    burn: int = 25
    seed: int = 0
    max_support: int = 4096
    kernel: str = "gibbs"
    fit_limit: int | None = None
    sample: int | None = None
    sample_seed: int = 0

    def checked(self) -> TemperSettings:
        """These settings, each checked (:class:`~ogm_ppl.learn.FitOptionError` names the first out of range)."""
        from ogm_ppl.priors.named import prior_kinds

        if not self.kinds or len(set(self.kinds)) != len(self.kinds):
            raise FitOptionError("kinds", f"give one or more distinct prior kinds, got {list(self.kinds)}")
        for k in self.kinds:
            if k not in prior_kinds():
                raise FitOptionError("kinds", f"{k!r} is not a prior kind; known: {', '.join(prior_kinds())}")
        if not self.betas or len(set(self.betas)) != len(self.betas):
            raise FitOptionError("betas", f"give one or more distinct exponents, got {list(self.betas)}")
        for b in self.betas:
            check_float(b, "betas", 0.0, 1.0, lo_open=False)
        check_int(self.plans, "plans", 1, 1000)
        check_int(self.window, "window", 8, 4096)
        check_int(self.generated_shape, "generated_shape", max(80, self.window), 4096)  # a 20-cell border
        check_int(self.poses, "poses", 1, 1000)
        check_int(self.beams, "beams", 1, 100_000)
        check_float(self.range_cells, "range_cells", 0.0, 1e5)
        check_float(self.sigma, "sigma", 0.0, 1e3)
        check_int(self.sweeps, "sweeps", 1, 10_000_000)
        check_int(self.burn, "burn", 0, 10_000_000)
        check_int(self.seed, "seed", 0, 2**31 - 1)
        check_int(self.max_support, "max_support", 2)
        if self.kernel not in _KERNELS:
            raise FitOptionError("kernel", f"must be one of {', '.join(_KERNELS)}, got {self.kernel!r}")
        if self.fit_limit is not None:
            check_int(self.fit_limit, "fit_limit", 1)
        if self.sample is not None:
            check_int(self.sample, "sample", 2)
        check_int(self.sample_seed, "sample_seed", 0, 2**32 - 1)
        if self.sample is None and self.sample_seed != 0:
            raise FitOptionError("sample_seed", "applies with --sample only (the seed of its random plans)")
        return TemperSettings(
            **{**asdict(self), "kinds": tuple(self.kinds), "betas": tuple(float(b) for b in self.betas)}
        )

    def record(self) -> dict:
        """The settings as the file records them."""
        d: dict[str, Any] = asdict(self)
        d["kinds"], d["betas"] = list(self.kinds), list(self.betas)
        return d

    def options(self) -> list[str]:
        """The command-line options that differ from the defaults."""
        out: list[str] = []
        for k, v in asdict(self).items():
            if v != getattr(_DEFAULTS, k):
                vals = [f"{x:g}" if isinstance(x, float) else str(x) for x in (v if isinstance(v, tuple) else [v])]
                out += ["--" + k.replace("_", "-"), *vals]
        return out


_DEFAULTS = TemperSettings()


def choose(scores: dict[float, list[float]]) -> float:
    """The ``beta`` with the lowest mean NLL (ties: the larger ``beta``)."""
    return min(scores, key=lambda b: (float(np.mean(scores[b])), -b))


def fit_temper(
    corpus: str | Sequence[str],
    out_dir: str | os.PathLike | None = None,
    *,
    settings: TemperSettings | None = None,
    update: bool = False,
    ship: bool = False,
    progress: bool = True,
) -> FitResult:
    """Choose the tempering exponent of each kind on each corpus's validation plans (module docstring) and
    write ``temper_<corpus>.json`` into ``out_dir`` (nothing else, atomically).

    Args:
        corpus: one corpus (``generated``, ``houseexpo``, ``ipa``, ``dungeon``) or several.
        out_dir: the folder the files go to (created if missing).
        settings: :class:`TemperSettings` (default: the shipped protocol).
        update: keep the other kinds of an existing file in the folder and refit only ``settings.kinds`` (refused
            before anything runs unless that file was fitted with the same protocol).
        ship: write into the package's ``ogm_ppl/fitted`` instead of ``out_dir`` (maintainers).
        progress: a line per kind and exponent.

    Raises:
        FitOptionError: an option out of range (the message names it and the limit).
    """
    s = (settings or TemperSettings()).checked()
    corpora = [corpus] if isinstance(corpus, str) else list(corpus)
    if not corpora or len(set(corpora)) != len(corpora) or any(c not in CORPORA for c in corpora):
        raise FitOptionError("corpus", f"give one or more distinct corpora of {', '.join(CORPORA)}, got {corpora}")
    if s.sample is not None and "generated" in corpora:
        raise FitOptionError("sample", "applies to floor-plan corpora only (the generated maps have no split)")
    for c in corpora:  # a file kind needs its fit on every corpus given: refused before anything is written
        for k in s.kinds:
            if k in FILE_KINDS:
                file_kind_path(k, c)
    out, where = output_folder(out_dir, ship)
    old = {c: _previous(out / f"temper_{c}.json", c, s) for c in corpora} if update else {}
    cmd = shell_command("temper", "--corpus", *corpora, *where, *s.options(), *(["--update"] if update else []))
    import torch

    from ogm_ppl.io import writable_folder
    from ogm_ppl.provenance import provenance

    writable_folder(out)
    prov = provenance(cmd)
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    t0 = time.perf_counter()
    try:
        docs = [_fit_corpus(c, s, prov, progress) for c in corpora]
    finally:
        torch.set_num_threads(threads)
    from ogm_ppl.io import atomic_write_text

    files = []
    for doc in docs:
        path = out / f"temper_{doc['corpus']}.json"
        previous = old.get(doc["corpus"])
        if previous is not None:
            doc = _merge(previous, doc)
        files.append(atomic_write_text(path, json.dumps(doc, indent=1) + "\n"))
        if progress:
            print(f"{doc['corpus']}: {doc['beta']} -> {path}", flush=True)
    summary = {
        "beta": {d["corpus"]: d["beta"] for d in docs},
        "validation": {d["corpus"]: d["validation"] for d in docs},
    }
    return FitResult("temper", tuple(files), prov, summary, round(time.perf_counter() - t0, 1))


def _fit_corpus(corpus: str, s: TemperSettings, prov: dict, progress: bool) -> dict:
    """The file of one corpus: every kind's exponent and scores."""
    from ogm_ppl.calibration import generated_windows, make_scene, run_prior
    from ogm_ppl.datasets import floorplans as fp

    t0 = time.perf_counter()
    rec: dict = {**prov, "excluded_buildings": list(fp.REAL_LOG_BUILDINGS)}
    table_kinds = [k for k in s.kinds if k not in FILE_KINDS]
    own = {k: file_kind_validation(k, corpus) for k in s.kinds if k in FILE_KINDS}  # refused before any work
    maps: list = []
    own_maps: dict[str, list] = {}
    if corpus == "generated":
        tables, counted = None, 0.0
        maps = generated_windows(s.plans, s.generated_shape, s.window, VALIDATION_SEED)
        rec.update(tables="shipped (ogm_ppl/fitted/prior_generated.npz)", validation_seed=VALIDATION_SEED)
    else:
        fit, val = split_names(corpus, s.sample, s.sample_seed)
        fit = fit[: s.fit_limit]
        own_maps = {k: validation_windows(corpus, names, s.plans, s.window) for k, names in own.items()}
        if table_kinds:
            maps = validation_windows(corpus, val, s.plans, s.window)  # refused before the counting
        tables = count_fit_tables(corpus, fit) if table_kinds else None
        counted = time.perf_counter() - t0
        rec.update(
            tables="counted on the fit part" if table_kinds else "none (file kinds only)",
            fit_plans=len(fit),
            fit_names_sha256=names_sha256(fit),
            validation_names_sha256=names_sha256(val),
        )
    scenes = [make_scene(t, s) for t in maps]
    validation: dict[str, dict] = {}
    beta: dict[str, float] = {}
    for kind in s.kinds:
        per: dict[float, list[float]] = {}
        rhat: dict[float, list[float]] = {}
        skipped = None
        kind_scenes = [make_scene(t, s) for t in own_maps[kind]] if kind in own else scenes
        for b in s.betas:
            name = f"{kind}:{corpus}" + ("" if b == 1.0 else f"@{b:g}")
            for sc in kind_scenes:
                r = run_prior(sc, name, s, tables=None if kind in own else tables)
                if "skipped" in r:
                    skipped = r["skipped"]
                    break
                per.setdefault(b, []).append(float(r["scores"]["unseen"]["nll_bits"]))
                rhat.setdefault(b, []).append(float(r["rhat_below"]))
            if skipped:
                break
            if progress:
                print(
                    f"  {corpus:>9} {kind:>10} beta {b:<5g} NLL {np.mean(per[b]):.3f} "
                    f"(R-hat<1.05 {np.mean(rhat[b]):.2f}; {time.perf_counter() - t0:.0f} s)",
                    flush=True,
                )
        if skipped:
            if progress:
                print(f"  {corpus:>9} {kind:>10} skipped: {skipped}", flush=True)
            continue
        beta[kind] = choose(per)
        validation[kind] = {
            "betas": list(per),
            "nll_bits": [per[b] for b in per],
            "mean_nll_bits": [float(np.mean(per[b])) for b in per],
            "rhat_below": [float(np.mean(rhat[b])) for b in per],
        }
        if kind in own:
            validation[kind].update(file_kind_record(kind, corpus, own_maps[kind], s, progress))
        if progress:
            print(f"  {corpus:>9} {kind:>10} -> beta {beta[kind]:g}", flush=True)
    rec.update(
        validation_plans_scored=[t.name for t in maps],
        fitted_by="ogm_ppl.learn.fit_temper",
        counting_seconds=round(counted, 1),
        seconds=round(time.perf_counter() - t0, 1),
    )
    from ogm_ppl.priors.named import TEMPER_FORMAT

    return {
        "format": TEMPER_FORMAT,
        "format_version": 1,
        "corpus": corpus,
        "beta": beta,
        "criterion": "mean NLL (bits per cell) of the unseen near-mapped cells over the validation plans; "
        "3 chains from different starts pooled (calibration.run_prior); ties -> the larger beta",
        "validation": validation,
        "settings": s.record(),
        "provenance": rec,
    }


def _protocol(settings: dict) -> dict:
    """The settings that define the protocol; a file recorded with ``quick`` counted 10 fit plans."""
    fit_limit = settings.get("fit_limit", 10 if settings.get("quick") else None)
    sample = {"sample": settings.get("sample"), "sample_seed": settings.get("sample_seed", 0)}
    return {**{k: settings.get(k) for k in _PROTOCOL}, "fit_limit": fit_limit, **sample}


def _previous(path: Path, corpus: str, s: TemperSettings) -> dict | None:
    """The file an update keeps the other kinds of (``None``: there is none), refused unless fitted with the
    same protocol."""
    if not path.is_file():
        return None
    from ogm_ppl.priors.named import load_temper_params

    try:
        load_temper_params(corpus, path=path)
        old = json.loads(path.read_text())
    except ValueError as e:
        raise FitOptionError("update", f"{path} is not a tempering file to update ({e})") from None
    if old.get("corpus") != corpus or _protocol(old.get("settings", {})) != _protocol(s.record()):
        raise FitOptionError("update", f"{path} was fitted with other settings; refit every kind instead")
    return old


def _merge(old: dict, new: dict) -> dict:
    """``old`` with ``new``'s kinds replaced."""
    out = dict(old)
    out["beta"] = {**old["beta"], **new["beta"]}
    out["validation"] = {**old["validation"], **new["validation"]}
    out["provenance"] = {**old["provenance"], "updated": new["provenance"]}
    return out
