r"""What limits a corpus guide's prediction of unseen cells: its calibration, or what it can tell apart?

On the held-out maps of a test corpus, under the calibration protocol of thesis Section 5.2.1
(:mod:`ogm_ppl.calibration`: the same windows, stop-and-scan data and unseen near-mapped cells ``U``), for each
guide ``g`` (names as ``ogm-ppl calibrate --guides`` takes them) :func:`guide_limits` reports, in bits per unseen
cell and as the mean over the ``P`` maps,

.. math::

    \mathrm{NLL}(q) = \frac{1}{P} \sum_{p=1}^{P} \Big( -\frac{1}{|U_p|} \sum_{k \in U_p}
        \log_2 q_k^{m_k} (1 - q_k)^{1 - m_k} \Big),

for these marginals ``q``:

* ``nll``: the guide as shipped, ``q = g`` (clipped to ``[EPS, 1 - EPS]``, as :func:`~ogm_ppl.metrics.nll_bits`
  clips);
* ``nll_oracle_temperature``: ``q = sigmoid(l / T)`` with ``l = logit(g)`` and the one temperature ``T`` in
  :data:`TEMPERATURES` that minimises the NLL *on these test maps*, and ``nll_oracle_affine``:
  ``q = sigmoid(l / T + b)`` with a shift ``b`` in :data:`SHIFTS` too. Fitted on the test maps themselves,
  these are lower bounds on what any recalibration of the guide's marginals (temperature scaling, Platt
  scaling; Guo et al. 2017) could reach; they leave the ranking of the cells, so AUC and best F1, unchanged.
  A guide whose NLL they barely lower is limited by what it tells apart, not by how it states its confidence;
* ``nll_ensemble``: ``q`` the mean of the guides' probabilities (a mixture);
* per map: its name, its unseen cells and their occupied share, and every guide's NLL, so that the buildings
  behind the mean are visible (several windows of a test corpus can be variants of one building).

The leakage checks of :mod:`ogm_ppl.calibration` apply: a guide is never scored on a plan (or building) it was
trained on.
"""

from __future__ import annotations

import json
import os
import time
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

from ogm_ppl import calibration as C
from ogm_ppl.calibration import SettingsError
from ogm_ppl.io import atomic_write_text, writable_folder
from ogm_ppl.metrics import nll_bits

__all__ = ["EPS", "SHIFTS", "TEMPERATURES", "guide_limits", "recalibrated"]

#: the temperatures ``T`` tried by the oracle recalibrations
TEMPERATURES = np.round(np.arange(0.5, 4.0001, 0.05), 3)
#: the shifts ``b`` tried by the affine oracle
SHIFTS = np.round(np.arange(-1.5, 1.5001, 0.125), 3)
#: the clip of :func:`ogm_ppl.metrics.nll_bits`: logits of clipped probabilities stay finite
EPS = 1e-6


def recalibrated(
    logits: Sequence[np.ndarray], ys: Sequence[np.ndarray], shifts: Sequence[float] | np.ndarray = (0.0,)
) -> tuple[float, float, float]:
    """``(mean NLL over maps, T, b)`` of ``sigmoid(l / T + b)`` at the best ``T`` in :data:`TEMPERATURES` and
    ``b`` in ``shifts``, chosen on these maps (``logits[p]`` and ``ys[p]``: the logits and 0/1 truth of map
    ``p``'s scored cells; the first best on ties)."""
    best = (np.inf, 1.0, 0.0)
    for T in TEMPERATURES:
        for b in shifts:
            v = float(np.mean([nll_bits(1 / (1 + np.exp(-(lg / T + b))), y) for lg, y in zip(logits, ys)]))
            if v < best[0]:
                best = (v, float(T), float(b))
    return best


def guide_limits(
    test: str,
    guides: Sequence[str],
    *,
    guide_dir: str | os.PathLike | None = None,
    plans: int = 10,
    out: str | os.PathLike | None = None,
    log: Callable[[str], None] | None = None,
) -> dict:
    """Score the ``guides`` on the first ``plans`` held-out maps of the test corpus ``test`` (module docstring).

    Args:
        test: a test corpus of :data:`~ogm_ppl.calibration.TEST_CORPORA`.
        guides: guide names as ``ogm-ppl calibrate --guides`` takes them; ``NAME=DIR`` reads the guide ``NAME``
            from ``DIR`` (another training of it), so several trainings of one guide can be compared.
        guide_dir: the folder the guides without ``=DIR`` are read from (default the shipped ones).
        plans: held-out maps of the test corpus.
        out: a folder to write ``guide_limits.json`` into (checked writable before any work); ``None`` writes
            nothing.
        log: called with one line per map (its name and every guide's NLL).

    Returns:
        The document as written, with ``"provenance"``, ``"settings"``, ``"rows"`` (one per map), ``"seconds"``
        and ``"summary"``, which holds per guide ``{"nll", "nll_oracle_temperature", "oracle_temperature",
        "nll_oracle_affine", "oracle_affine": [T, b]}`` and ``"ensemble": {"nll", "of"}``.

    Raises:
        SettingsError: ``out`` not writable, ``plans`` below 1 or ``test`` not a test corpus (``option`` names
            which).
        LeakageError: a guide trained on a plan of the test maps.
        GuideNameError: a guide name that names no guide.
    """
    from ogm_ppl import GaussianRange, OccupancyModel
    from ogm_ppl.priors import IndependentPrior
    from ogm_ppl.provenance import provenance

    if out is not None:
        try:
            writable_folder(out)
        except OSError as e:
            raise SettingsError("out", str(e)) from None
    if plans < 1:
        raise SettingsError("plans", "must be at least 1")
    if test not in C.TEST_CORPORA:
        raise SettingsError("test", f"{test!r} is not a test corpus ({', '.join(C.TEST_CORPORA)})")
    say = log or (lambda line: None)
    proto = C.CalibrationSettings(plans=plans)  # the calibration protocol, at its defaults
    maps = C.heldout_maps(test, plans, proto.window, proto.generated_shape)
    loaded = {}
    for entry in guides:  # NAME, or NAME=DIR: the guide NAME read from DIR (another training of it)
        name, _, folder = entry.partition("=")
        loaded[entry] = C.guide_for(name, Path(folder) if folder else (None if guide_dir is None else Path(guide_dir)))
        trained = C.guide_training_sets(name.removesuffix(C.GUIDE_SYM), loaded[entry].trained_for)
        for c, train in trained.items():  # the training maps the guide's record names, per corpus
            C.check_heldout(test, [t.plan for t in maps], c, train)
    t0 = time.perf_counter()
    rows: list[dict] = []
    logits: dict[str, list[np.ndarray]] = {g: [] for g in loaded}
    ys = []
    for t in maps:
        scene = C.make_scene(t, proto)
        model = OccupancyModel(
            scene.grid, scene.rays, GaussianRange(proto.sigma), IndependentPrior(0.5, scene.grid.num_cells)
        )
        unseen = scene.masks["unseen"]
        y = t.truth.ravel()[unseen].astype(np.float64)
        ys.append(y)
        row: dict = {"plan": t.name, "unseen_cells": int(unseen.sum()), "occupied_share": float(y.mean())}
        probs = []
        for g, guide in loaded.items():
            q = np.clip(guide.marginals(model).numpy()[unseen], EPS, 1 - EPS)
            logits[g].append(np.log(q / (1 - q)))
            probs.append(q)
            row[g] = nll_bits(q, y)
        row["ensemble"] = nll_bits(np.mean(probs, axis=0), y)
        rows.append(row)
        say(f"  {t.name[:40]:<40} " + " ".join(f"{k} {v:.3f}" for k, v in row.items() if k in loaded))
    summary: dict[str, dict] = {}
    for g in loaded:
        t_only = recalibrated(logits[g], ys)
        affine = recalibrated(logits[g], ys, SHIFTS)
        summary[g] = {
            "nll": float(np.mean([r[g] for r in rows])),
            "nll_oracle_temperature": t_only[0],
            "oracle_temperature": t_only[1],
            "nll_oracle_affine": affine[0],
            "oracle_affine": [affine[1], affine[2]],
        }
    summary["ensemble"] = {"nll": float(np.mean([r["ensemble"] for r in rows])), "of": list(loaded)}
    doc = {
        "provenance": provenance(),
        "settings": {
            "test": test,
            "guides": list(guides),
            "guide_dir": None if guide_dir is None else str(guide_dir),
            "plans": plans,
            "protocol": {k: getattr(proto, k) for k in ("window", "poses", "beams", "range_cells", "sigma", "seed")},
            "temperatures": [float(TEMPERATURES[0]), float(TEMPERATURES[-1])],
            "shifts": [float(SHIFTS[0]), float(SHIFTS[-1])],
        },
        "rows": rows,
        "summary": summary,
        "seconds": time.perf_counter() - t0,
    }
    if out is not None:
        atomic_write_text(Path(out) / "guide_limits.json", json.dumps(doc, indent=1))
    return doc
