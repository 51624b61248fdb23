r"""The prior of the headline experiment (``make run``), chosen on training plans, never on the Intel log.

The protocol (thesis Section 6.2.1's setting, scored as Fig. 6.16b scores). The corpus's training plans are
split as :func:`~ogm_ppl.learn.fit_backoff` splits them: every fifth plan (``index % 5 == 4``) is validation,
the rest fit. Every table is counted on the fit part only (8 symmetries, ``min_count_5x5 = 2``); the
backed-off kinds use the shipped Witten-Bell ``kappa``, chosen on exactly this split. On ``plans`` validation
plans, each cropped to the ``window`` holding the most wall-side cells
(:func:`~ogm_ppl.calibration.choose_window`), a sparse stop-and-scan dataset is simulated
(:func:`~ogm_ppl.calibration.make_scene`: ``poses`` stops of a frontier route, ``beams`` beams, range
``range_cells``, range noise ``sigma`` cells: the headline's Gibbs sensor model), and every candidate
``(kind, update)`` maps it as the headline does: patch Gibbs with ``L = 9`` (3 x 3 patches, Algorithm 2) from
the thresholded OGM start, ``sweeps`` sweeps after ``burn``, marginals ``q_k`` the running means. On the
near-mapped mask ``N`` (cells within 10 cells of a reached cell) each candidate's best F1 and ROC AUC are
scored, and the winner is

.. math::

    \hat c = \arg\max_{c} \Big( \frac{1}{P} \sum_{p=1}^{P} \max_t F_1(\{k \in N_p: q_{c,k} > t\}),\;
        \frac{1}{P} \sum_{p=1}^{P} \mathrm{AUC}_{c,p} \Big)

(lexicographic: the mean best F1, AUC breaking ties); traditional OGM (Hähnel) is scored beside them as a
reference and never chosen.

:func:`select_headline_prior` writes ``headline_prior.json`` (the winner's ``prior`` kind, ``corpus`` and
kernel ``update``, every candidate's scores, the settings and provenance), which
:func:`ogm_ppl.experiment.headline.headline_prior` reads and validates
(``ogm-ppl fit-prior headline --out DIR``; ``--ship`` replaces ``ogm_ppl/fitted/headline_prior.json``).
"""

from __future__ import annotations

import json
import os
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from ogm_ppl.learn._fit_common import FitOptionError, FitResult, check_float, check_int, check_label
from ogm_ppl.learn._heldout import (
    count_fit_tables,
    names_sha256,
    output_folder,
    shell_command,
    split_names,
    validation_windows,
)

__all__ = [
    "CANDIDATES",
    "HEADLINE_CORPORA",
    "HEADLINE_PRIOR_FORMAT",
    "UPDATES",
    "HeadlineSettings",
    "select_headline_prior",
]

#: the ``format`` field of ``headline_prior.json``
HEADLINE_PRIOR_FORMAT = "ogm_ppl.headline_prior"
#: the patch-Gibbs updates (``"gibbs"``: the exact conditional; ``"thesis"``: the thesis's border update)
UPDATES: tuple[str, ...] = ("gibbs", "thesis")
#: the floor-plan corpora a selection can run on
HEADLINE_CORPORA: tuple[str, ...] = ("houseexpo", "ipa", "dungeon")
#: ``(kind, update)`` pairs tried
CANDIDATES: tuple[tuple[str, str], ...] = (
    ("patch3", "gibbs"),
    ("patch3_bo", "gibbs"),
    ("border", "gibbs"),
    ("border", "thesis"),
    ("border_bo", "gibbs"),
    ("mrf", "gibbs"),
)
#: the file written
FILE_NAME = "headline_prior"


@dataclass(frozen=True)
class HeadlineSettings:
    """The settings of :func:`select_headline_prior` (defaults: the shipped selection). ``corpus``; ``plans``
    validation plans of ``window`` cells a side; the scan: ``poses`` stops, ``beams`` beams, ``range_cells``,
    range noise ``sigma`` cells; the sampler: ``sweeps`` after ``burn``, ``seed``; the ``candidates``
    ``(kind, update)``; ``fit_limit``: count the tables on the first ``fit_limit`` fit plans only (a quick
    run; ``None``: all)."""

    corpus: str = "houseexpo"
    plans: int = 8
    window: int = 128
    poses: int = 4
    beams: int = 180
    range_cells: float = 75.0
    sigma: float = 0.5
    sweeps: int = 60
    burn: int = 10
    seed: int = 0
    candidates: tuple[tuple[str, str], ...] = CANDIDATES
    fit_limit: int | None = None

    def checked(self) -> HeadlineSettings:
        """These settings, each checked (:class:`~ogm_ppl.learn.FitOptionError` names the first out of range)."""
        from ogm_ppl.priors.named import prior_kinds

        if self.corpus not in HEADLINE_CORPORA:
            raise FitOptionError("corpus", f"must be one of {', '.join(HEADLINE_CORPORA)}, got {self.corpus!r}")
        check_int(self.plans, "plans", 1, 1000)
        check_int(self.window, "window", 8, 4096)
        check_int(self.poses, "poses", 1, 1000)
        check_int(self.beams, "beams", 1, 100_000)
        check_float(self.range_cells, "range_cells", 0.0, 1e5)
        check_float(self.sigma, "sigma", 0.0, 1e3)
        check_int(self.sweeps, "sweeps", 1, 10_000_000)
        check_int(self.burn, "burn", 0, 10_000_000)
        check_int(self.seed, "seed", 0, 2**31 - 1)
        cands = tuple((str(k), str(u)) for k, u in self.candidates)
        if not cands or len(set(cands)) != len(cands):
            raise FitOptionError("candidates", f"give one or more distinct KIND/UPDATE pairs, got {list(cands)}")
        for kind, update in cands:
            if kind not in prior_kinds() or update not in UPDATES:
                raise FitOptionError(
                    "candidates", f"{kind}/{update}: KIND must be a prior kind and UPDATE one of {', '.join(UPDATES)}"
                )
        if self.fit_limit is not None:
            check_int(self.fit_limit, "fit_limit", 1)
        return HeadlineSettings(**{**asdict(self), "candidates": cands})

    def record(self) -> dict:
        """The settings as the file records them."""
        d: dict[str, Any] = asdict(self)
        d["candidates"] = [f"{k}/{u}" for k, u in self.candidates]
        return d

    def options(self) -> list[str]:
        """The command-line options that differ from the defaults."""
        out: list[str] = []
        for k, v in asdict(self).items():
            if v == getattr(_DEFAULTS, k):
                continue
            if k == "candidates":
                out += ["--candidates", *(f"{a}/{b}" for a, b in v)]
            else:
                out += ["--" + k.replace("_", "-"), f"{v:g}" if isinstance(v, float) else str(v)]
        return out


_DEFAULTS = HeadlineSettings()


def _score(q: np.ndarray, truth: np.ndarray, near: np.ndarray) -> dict:
    from ogm_ppl.metrics import prediction_scores

    s = prediction_scores(q, truth.ravel(), mask=near.ravel())
    return {"best_f1": float(s["best_f1"]), "auc": float(s["auc"]), "nll_bits": float(s["nll_bits"])}


def run_candidate(kind: str, update: str, tables: Any, scene: Any, s: HeadlineSettings) -> dict:
    """One candidate's map of a scene (:class:`~ogm_ppl.calibration.Scene`), scored on its near-mapped cells:
    ``{"best_f1", "auc", "nll_bits", "seconds"}``."""
    from ogm_ppl import GaussianRange, OccupancyModel
    from ogm_ppl.inference import PatchGibbs, RunningStats, run_gibbs
    from ogm_ppl.priors.named import prior_by_name

    prior = prior_by_name(f"{kind}:{s.corpus}", scene.grid.shape, tables=tables)
    model = OccupancyModel(scene.grid, scene.rays, GaussianRange(s.sigma), prior)
    t0 = time.perf_counter()
    kernel = PatchGibbs(model, (3, 3), update=update)
    stats = RunningStats(model)
    run_gibbs(kernel, s.sweeps, stats, warmup=s.burn, seed=s.seed, progress=False)
    out = _score(np.clip(stats.marginals.numpy(), 0.0, 1.0), scene.tmap.truth, scene.masks["near"])
    out["seconds"] = time.perf_counter() - t0
    return out


def select_headline_prior(
    out_dir: str | os.PathLike | None = None,
    *,
    settings: HeadlineSettings | None = None,
    name: str = FILE_NAME,
    ship: bool = False,
    progress: bool = True,
) -> FitResult:
    """Score every candidate on the corpus's validation plans (module docstring) and write ``<name>.json``
    (``headline_prior.json``) into ``out_dir`` (nothing else, atomically).

    Args:
        out_dir: the folder the file goes to (created if missing).
        settings: :class:`HeadlineSettings` (default: the shipped selection's).
        name: the file's name part (the headline reads ``headline_prior.json``).
        ship: write ``ogm_ppl/fitted/headline_prior.json``, the package's own selection (maintainers).
        progress: a line per plan and candidate, and the table of means.

    Raises:
        FitOptionError: an option out of range (the message names it and the limit).
    """
    s = (settings or HeadlineSettings()).checked()
    label = check_label(name)
    if ship and label != FILE_NAME:
        raise FitOptionError("name", f"the shipped selection is {FILE_NAME}.json; give no other name with ship")
    out, where = output_folder(out_dir, ship)
    cmd = shell_command("headline", *where, *s.options(), *([] if label == FILE_NAME else ["--name", label]))
    from ogm_ppl.calibration import make_scene
    from ogm_ppl.datasets import floorplans as fp
    from ogm_ppl.inference import evidence_grid
    from ogm_ppl.io import atomic_write_text, writable_folder
    from ogm_ppl.models import delta_by_name
    from ogm_ppl.provenance import provenance

    t0 = time.perf_counter()
    fit, val = split_names(s.corpus)
    fit = fit[: s.fit_limit]
    maps = validation_windows(s.corpus, val, s.plans, s.window)  # refused before the counting
    writable_folder(out)
    tables = count_fit_tables(s.corpus, fit)
    counted = time.perf_counter() - t0
    scenes = [make_scene(t, s) for t in maps]
    rows = []
    for sc in scenes:
        plan, truth, near = sc.tmap.plan, sc.tmap.truth, sc.masks["near"]
        ogm = evidence_grid(sc.rays, delta_by_name("haehnel"))
        rows.append({"plan": plan, "candidate": "ogm", **_score(ogm.probabilities.numpy(), truth, near)})
        for kind, update in s.candidates:
            r = run_candidate(kind, update, tables, sc, s)
            rows.append({"plan": plan, "candidate": f"{kind}/{update}", **r})
            if progress:
                f1, auc, sec = r["best_f1"], r["auc"], r["seconds"]
                print(f"{plan:>24}  {kind:>10} {update:>6}  F1 {f1:.3f}  AUC {auc:.3f}  {sec:.1f} s", flush=True)
    names = [f"{k}/{u}" for k, u in s.candidates]
    means = {}
    for cand in ["ogm", *names]:
        rs = [r for r in rows if r["candidate"] == cand]
        means[cand] = {key: float(np.mean([r[key] for r in rs])) for key in ("best_f1", "auc", "nll_bits")}
    kind, update = max(names, key=lambda n: (means[n]["best_f1"], means[n]["auc"])).split("/")
    prov = {
        **provenance(cmd),
        "fit_names_sha256": names_sha256(fit),
        "validation_names_sha256": names_sha256(val),
        "fit_plans": len(fit),
        "validation_plans_scored": [sc.tmap.plan for sc in scenes],
        "excluded_buildings": list(fp.REAL_LOG_BUILDINGS),
        "selected_by": "ogm_ppl.learn.select_headline_prior",
        "counting_seconds": round(counted, 1),
        "seconds": round(time.perf_counter() - t0, 1),
    }
    doc = {
        "format": HEADLINE_PRIOR_FORMAT,
        "format_version": 1,
        "prior": kind,
        "corpus": s.corpus,
        "update": update,
        "criterion": "mean best F1 on the near-mapped mask of the validation plans (AUC breaks ties)",
        "means": means,
        "rows": rows,
        "settings": s.record(),
        "provenance": prov,
    }
    path = atomic_write_text(out / f"{label}.json", json.dumps(doc, indent=1) + "\n")
    if progress:
        print("\nmean over plans (near-mapped mask):")
        for cand, m in means.items():
            print(f"  {cand:>18}  F1 {m['best_f1']:.3f}  AUC {m['auc']:.3f}  NLL {m['nll_bits']:.3f}")
        print(f"chosen: {kind}:{s.corpus} (update {update}) -> {path}", flush=True)
    summary = {"prior": kind, "corpus": s.corpus, "update": update, "means": means}
    return FitResult("headline", (path,), prov, summary, prov["seconds"])


def candidates_from(pairs: Sequence[str]) -> tuple[tuple[str, str], ...]:
    """``KIND/UPDATE`` strings as ``(kind, update)`` pairs (:class:`FitOptionError` naming ``candidates``)."""
    out = []
    for p in pairs:
        kind, sep, update = str(p).partition("/")
        if not sep or not kind or not update:
            raise FitOptionError("candidates", f"give each as KIND/UPDATE (border/gibbs), got {p!r}")
        out.append((kind, update))
    return tuple(out)
