r"""Where a method's bits go on the unseen cells: NLL by distance to the nearest cell some ray reached.

The protocol of ``ogm-ppl calibrate`` (thesis Section 5.2.1: the same held-out maps, windows, stop-and-scan
data and unseen cells ``U``, near-mapped cells no ray reached), and one method: an amortised guide (a name
``ogm-ppl calibrate --guides`` takes, e.g. ``houseexpo+ipa@sym``) or a prior sampled by chains (a prior name; a
name without ``:CORPUS`` is learned on each test corpus's own training plans, as ``ogm-ppl calibrate
--diagonal`` runs it), with the calibration run's leakage checks. Each unseen cell ``k`` is binned by its
Euclidean distance ``d_k`` (in cells) to the nearest reached cell, on the bins of :data:`EDGES`; per test
corpus and bin ``B`` (summed over the corpus's maps): the share of the unseen cells in it, their occupied
share and the method's NLL in bits per cell,

.. math::

    \mathrm{NLL}_B = -\frac{1}{|B|} \sum_{k \in B} \log_2 q_k^{m_k} (1 - q_k)^{1 - m_k}

(``q`` clipped as :func:`~ogm_ppl.metrics.nll_bits` clips it). The bins' NLLs weighted by their shares give
the pooled NLL over the corpus's unseen cells (``ogm-ppl calibrate`` reports the mean over maps instead; for
one map the two agree).

A prior runs the calibration protocol's ``C = 3`` chains (:func:`~ogm_ppl.calibration.run_prior_chains`; ``q``
their pooled marginals), and each bin also gets the share of its cells whose chains agree (split R-hat below
:data:`~ogm_ppl.calibration.RHAT_THRESHOLD`) and each chain's mean occupancy there. Several chain lengths
give one run each, from the same seeds, so agreement can be followed as the chains grow longer.

Plan files (:class:`DistanceSettings`' ``plan_files``, ``plan_set``, ``pixel_size``, ``plan_outside``, as
``ogm-ppl calibrate`` takes them) are binned too, as one more test set; a prior run on them must name its
corpus (``KIND:CORPUS``).
"""

from __future__ import annotations

import dataclasses
import os
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

import ogm_ppl.calibration as calibration
from ogm_ppl.calibration import CalibrationError, CalibrationSettings, SettingsError

__all__ = [
    "DEFAULT_GUIDE",
    "EDGES",
    "TESTS",
    "DistanceSettings",
    "PriorSkippedError",
    "chains_by_distance",
    "guide_by_distance",
    "rows_table",
    "unseen_by_distance",
]

#: bin edges of the distance to the nearest reached cell, in cells: (0, 1.5] holds the 8 neighbours
EDGES: tuple[float, ...] = (0.0, 1.5, 3.0, 6.0, float("inf"))
#: the test corpora
TESTS: tuple[str, ...] = ("generated", "houseexpo", "ipa", "dungeon")
#: the guide binned when neither a guide nor a prior is named
DEFAULT_GUIDE = "houseexpo+ipa@sym"
#: held-out maps per test corpus when ``plans`` is not given (plan files: all of them)
DEFAULT_PLANS = 10


class PriorSkippedError(CalibrationError):
    """The prior's chains cannot run on a map (an update would weigh more configurations than the protocol
    allows, or a ``@cal`` name has no fitted exponent); the message names the prior, the map and why."""


@dataclass(frozen=True)
class DistanceSettings:
    """What :func:`unseen_by_distance` bins. The method: ``guide`` (read from ``guide_dir``, default the
    shipped guides) or ``prior`` (sampled by the ``kernel`` of :data:`~ogm_ppl.calibration.KERNELS`, one run per
    value of ``sweeps``, kept sweeps per chain, after ``burn`` warm-up sweeps, default a quarter of each);
    neither: :data:`DEFAULT_GUIDE`. The maps: ``test`` corpora of :data:`TESTS` (default all, or none with
    ``plan_files``), ``plans`` held-out maps per corpus (default :data:`DEFAULT_PLANS`; every plan of the plan
    files), the plan files' ``plan_set`` label, ``pixel_size`` and ``plan_outside``. The sensor and window are
    the calibration protocol's defaults (:class:`~ogm_ppl.calibration.CalibrationSettings`).

    Raises :class:`~ogm_ppl.calibration.SettingsError` naming the first setting out of range (``sweeps`` below
    4: split R-hat halves each chain) or settings that do not go together (both a guide and a prior)."""

    guide: str | None = None
    prior: str | None = None
    guide_dir: Path | None = None
    kernel: str = "cycle"
    sweeps: tuple[int, ...] = (200,)
    burn: int | None = None
    test: tuple[str, ...] | None = None
    plans: int | None = None
    plan_files: tuple[Path, ...] | None = None
    plan_set: str = "files"
    pixel_size: float | None = None
    plan_outside: str = "occupied"

    def __post_init__(self) -> None:
        norm = object.__setattr__  # frozen: normalise the given sequences once
        norm(self, "sweeps", tuple(dict.fromkeys(int(s) for s in self.sweeps)))  # one run per distinct length
        if self.test is not None:
            norm(self, "test", tuple(self.test))
        if self.plan_files is not None:
            norm(self, "plan_files", tuple(Path(p) for p in self.plan_files) or None)
        if self.guide_dir is not None:
            norm(self, "guide_dir", Path(self.guide_dir))
        if self.guide is not None and self.prior is not None:
            raise SettingsError("prior", "give a guide or a prior, not both")
        if self.plans is not None and self.plans < 1:
            raise SettingsError("plans", "must be at least 1")
        if not self.sweeps or min(self.sweeps) < 4:
            raise SettingsError("sweeps", "must be at least 4 (split R-hat halves each chain)")
        if self.burn is not None and self.burn < 0:
            raise SettingsError("burn", "must be at least 0")
        if self.kernel not in calibration.KERNELS:
            raise SettingsError(
                "kernel", f"{self.kernel!r} is not a sampler ({', '.join(sorted(calibration.KERNELS))})"
            )
        for c in self.test or ():
            if c not in TESTS:
                raise SettingsError("test", f"{c!r} is not a test corpus ({', '.join(TESTS)})")
        self.protocol()  # the plan-file options, checked as the calibration run checks them

    def protocol(self, sweeps: int | None = None) -> CalibrationSettings:
        """The calibration protocol's settings for these maps (and chains of ``sweeps`` kept sweeps)."""
        s = CalibrationSettings(
            plans=self.plans,
            plan_files=self.plan_files,
            plan_set=self.plan_set,
            pixel_size=self.pixel_size,
            plan_outside=self.plan_outside,
            kernel=self.kernel,
        )
        if sweeps is None:
            return s
        return dataclasses.replace(s, sweeps=sweeps, burn=sweeps // 4 if self.burn is None else self.burn)

    @property
    def maps_per_corpus(self) -> int:
        """Held-out maps per test corpus: ``plans``, else :data:`DEFAULT_PLANS`."""
        return DEFAULT_PLANS if self.plans is None else self.plans

    @property
    def tests(self) -> list[str]:
        """The test sets binned: the corpora, then the plan set."""
        test = list(self.test) if self.test is not None else ([] if self.plan_files else list(TESTS))
        return test + ([self.plan_set] if self.plan_files else [])


def _bins(d: np.ndarray, unseen: np.ndarray) -> list[np.ndarray]:
    return [unseen & (d > EDGES[i]) & (d <= EDGES[i + 1]) for i in range(len(EDGES) - 1)]


def _maps(
    test: str, s: DistanceSettings, train_corpora: Sequence[str | None], train_sets: Sequence[set[str] | None] = ()
) -> list[calibration.TestMap]:
    """The test set's maps, checked against each training corpus (``None``: a prior learned from nothing) and,
    where given, its training maps (``train_sets[i]``, default the corpus's tables' training set)."""
    if s.plan_files and test == s.plan_set:
        maps = calibration.plan_set_maps(s.protocol(), s.plans)
    else:
        maps = calibration.heldout_maps(test, s.maps_per_corpus, s.protocol().window)
    sets = list(train_sets) + [None] * (len(train_corpora) - len(train_sets))
    for corpus, train in zip(train_corpora, sets, strict=True):  # never a map of the method's training plans
        calibration.check_heldout(test, [t.plan for t in maps], corpus, train)
    return maps


def _distance(scene: calibration.CalibrationScene) -> np.ndarray:
    from scipy.ndimage import distance_transform_edt

    return distance_transform_edt(~scene.rays.reached().reshape(scene.grid.shape))


def _bits(q: np.ndarray, truth: np.ndarray, m: np.ndarray) -> float:
    """The summed NLL in bits of the cells ``m``, under :func:`~ogm_ppl.metrics.nll_bits`'s clipping."""
    from ogm_ppl.metrics import nll_bits

    return nll_bits(q, truth, m) * int(m.sum()) if m.any() else 0.0


def _add(acc: dict, bins: list[np.ndarray], q: np.ndarray, truth: np.ndarray) -> None:
    """Add one map's bins to the sums ``acc["n"]``, ``acc["bits"]`` and ``acc["occ"]`` (cells, NLL bits,
    occupied cells per bin) under the marginals ``q``."""
    for i, m in enumerate(bins):
        acc["n"][i] += m.sum()
        acc["bits"][i] += _bits(q, truth, m)
        acc["occ"][i] += truth[m].sum()


def _sums(nb: int) -> dict:
    return {"n": np.zeros(nb), "bits": np.zeros(nb), "occ": np.zeros(nb)}


def _rows(test: str, maps: int, n, bits, occ, extra: dict | None = None) -> list[dict]:
    total = max(n.sum(), 1)
    rows = []
    for i in range(len(EDGES) - 1):
        row = {
            "test": test,
            "maps": maps,
            "distance": [EDGES[i], EDGES[i + 1] if np.isfinite(EDGES[i + 1]) else None],  # None: no upper edge
            "cells": int(n[i]),
            "share": float(n[i] / total),
            "occupied_share": float(occ[i] / max(n[i], 1)),
            "nll_bits": float(bits[i] / max(n[i], 1)),
        }
        for key, v in (extra or {}).items():
            row[key] = v[i]
        rows.append(row)
    return rows


def guide_by_distance(test: str, guide: Any, name: str, settings: DistanceSettings) -> list[dict]:
    """The rows of one test set under the guide ``guide`` (named ``name``, for the leakage checks): per bin of
    :data:`EDGES`, ``{"test", "maps", "distance": [lo, hi or None], "cells", "share", "occupied_share",
    "nll_bits"}``."""
    from ogm_ppl import GaussianRange, OccupancyModel
    from ogm_ppl.priors import IndependentPrior

    acc = _sums(len(EDGES) - 1)
    trained = calibration.guide_training_sets(name.removesuffix(calibration.GUIDE_SYM), guide.trained_for)
    maps = _maps(test, settings, list(trained), list(trained.values()))
    proto = settings.protocol()
    for t in maps:
        scene = calibration.make_scene(t, proto)
        model = OccupancyModel(
            scene.grid, scene.rays, GaussianRange(proto.sigma), IndependentPrior(0.5, scene.grid.num_cells)
        )
        q = guide.marginals(model).numpy().reshape(t.truth.shape)
        _add(acc, _bins(_distance(scene), scene.masks["unseen"].reshape(t.truth.shape)), q, t.truth.astype(bool))
    return _rows(test, len(maps), acc["n"], acc["bits"], acc["occ"])


def _prior_name(test: str, prior: str) -> tuple[str, str | None]:
    """``(KIND:TRAIN[@MOD], TRAIN)``: the prior learned on ``test`` unless ``prior`` names a corpus; refused on a
    plan set that names none."""
    name, train = calibration.prior_names([prior], [test])[-1]  # KIND:TEST[@MOD] unless it names a corpus
    if test not in TESTS and train == test:
        raise SettingsError("prior", f"{prior}: no prior is learned on the plan set {test!r}; name one as KIND:CORPUS")
    return name, train


def chains_by_distance(test: str, settings: DistanceSettings, log: Callable[[str], None] | None = None) -> list[dict]:
    """The rows of one test set under the prior ``settings.prior``'s chains, one set per ``settings.sweeps``
    value: per bin, :func:`guide_by_distance`'s fields, plus ``"prior"``, ``"sweeps"``, ``"agree"`` (share of
    the bin's cells whose split R-hat is below the threshold) and ``"chain_occupied"`` (each chain's mean
    marginal over the bin's cells, in :data:`~ogm_ppl.calibration.STARTS` order). ``log`` gets a line per map
    and length (the share of its unseen cells whose chains agree).

    Raises:
        PriorSkippedError: the chains cannot run on a map.
    """
    assert settings.prior is not None, "chains_by_distance needs a prior"
    say = log or (lambda line: None)
    name, train = _prior_name(test, settings.prior)
    maps = _maps(test, settings, [train])
    nb, C = len(EDGES) - 1, len(calibration.STARTS)
    acc = {S: {**_sums(nb), "ok": np.zeros(nb), "chain": np.zeros((nb, C))} for S in settings.sweeps}
    for t in maps:
        scene = calibration.make_scene(t, settings.protocol())
        truth = t.truth.astype(bool)
        unseen_2d = scene.masks["unseen"].reshape(t.truth.shape)
        bins = _bins(_distance(scene), unseen_2d)
        idx = np.flatnonzero(unseen_2d.ravel())  # the order of run["rhat"]
        for S in settings.sweeps:
            run = calibration.run_prior_chains(scene, name, settings.protocol(S))
            if "skipped" in run:
                raise PriorSkippedError(f"{name} on {t.name}: {run['skipped']}")
            marg = run["marginals"].reshape(C, *t.truth.shape)
            agree = np.zeros(t.truth.shape, bool)
            agree.ravel()[idx] = calibration.agreeing(run["rhat"])
            a = acc[S]
            _add(a, bins, np.clip(marg.mean(0), 0.0, 1.0), truth)
            for i, m in enumerate(bins):
                a["ok"][i] += agree[m].sum()
                a["chain"][i] += marg[:, m].sum(1)
            say(f"  {t.name} {name} {S} sweeps: agree {agree.ravel()[idx].mean():.3f}")
    rows = []
    for S, a in acc.items():
        n = np.maximum(a["n"], 1)
        extra = {
            "agree": [float(a["ok"][i] / n[i]) for i in range(nb)],
            "chain_occupied": [[float(v / n[i]) for v in a["chain"][i]] for i in range(nb)],
        }
        for r in _rows(test, len(maps), a["n"], a["bits"], a["occ"], extra):
            rows.append({"prior": name, "sweeps": S, **r})
    return rows


def rows_table(rows: Sequence[dict], what: str) -> str:
    """The rows as a plain-text table headed by ``what`` (the method): test set, distance bin, share,
    occupied share, NLL bits, and for chains the sweeps, agreement share and each chain's occupancy."""
    chains = "agree" in rows[0]
    lines = [f"{what}, unseen cells by distance to the nearest reached cell (cells)"]
    head = f"{'test':10s} {'distance':>10s} {'share':>6s} {'occupied':>9s} {'NLL bits':>9s}"
    lines.append(
        head + (f" {'sweeps':>7s} {'agree':>6s}  chain occupancy ({', '.join(calibration.STARTS)})" if chains else "")
    )
    for r in rows:
        lo, hi = r["distance"]
        span = f"({lo:g}, {'inf' if hi is None else f'{hi:g}'}]"
        line = f"{r['test']:10s} {span:>10s} {r['share']:6.2f} {r['occupied_share']:9.2f} {r['nll_bits']:9.3f}"
        if chains:
            line += f" {r['sweeps']:7d} {r['agree']:6.2f}  " + " ".join(f"{v:.2f}" for v in r["chain_occupied"])
        lines.append(line)
    return "\n".join(lines)


def unseen_by_distance(
    settings: DistanceSettings,
    out: str | os.PathLike | None = None,
    *,
    log: Callable[[str], None] | None = None,
) -> dict:
    """Bin every test set of ``settings`` (module docstring) and, with ``out``, write
    ``out/unseen_by_distance.json``.

    Returns:
        The document as written, ``{"provenance", "settings", "rows", "seconds"}``, with the rows of
        :func:`guide_by_distance` or :func:`chains_by_distance` for each test set in turn.

    Raises:
        SettingsError: a prior without a corpus on a plan set.
        PriorSkippedError: a prior's chains cannot run on a map.
        LeakageError, GuideNameError, NoUsablePlanError, PlanFileError: as the calibration run raises them.
    """
    import json

    from ogm_ppl.io import atomic_write_text
    from ogm_ppl.provenance import provenance

    s = settings
    tests = s.tests
    if s.prior is not None:
        for test in tests:  # refused before any work
            _prior_name(test, s.prior)
    t0 = time.perf_counter()
    method: dict[str, Any]
    if s.prior is not None:
        rows = [r for test in tests for r in chains_by_distance(test, s, log)]
        method = {"prior": s.prior, "kernel": s.kernel, "sweeps": list(s.sweeps), "burn": s.burn}
    else:
        name = s.guide or DEFAULT_GUIDE
        guide = calibration.guide_for(name, s.guide_dir)
        rows = [r for test in tests for r in guide_by_distance(test, guide, name, s)]
        method = {"guide": name, "guide_dir": None if s.guide_dir is None else str(s.guide_dir)}
    files = (
        {
            "plan_files": [str(p) for p in s.plan_files],
            "plan_set": s.plan_set,
            "pixel_size": s.pixel_size,
            "plan_outside": s.plan_outside,
        }
        if s.plan_files
        else {}
    )
    doc = {
        "provenance": provenance(),
        "settings": {
            **method,
            "plans": s.maps_per_corpus,
            "window": s.protocol().window,
            "edges": [e if np.isfinite(e) else None for e in EDGES],
            **files,
        },
        "rows": rows,
        "seconds": time.perf_counter() - t0,
    }
    if out is not None:
        Path(out).mkdir(parents=True, exist_ok=True)
        atomic_write_text(Path(out) / "unseen_by_distance.json", json.dumps(doc, indent=1, allow_nan=False))
    return doc
