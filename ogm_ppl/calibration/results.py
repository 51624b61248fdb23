"""The rows of a calibration run and what is made of them (thesis Section 5.2.3).

A row is one (test corpus, map, method, mask): the scores of :func:`~ogm_ppl.calibration.scenes.score_marginals`
with the reliability diagram, the seconds, and for a prior the chains' R-hat share. It records the digest of
what it scored (:func:`~ogm_ppl.calibration.names.name_digest`), so a rerun into the same folder resumes: it
keeps the rows of its settings (:func:`load_previous`, which refuses a file of other :data:`RUN_KEYS`) and
computes again those of a method that changed since (:func:`drop_changed`). :func:`summary` averages the rows
over maps.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from ogm_ppl.calibration.errors import ResultFileError, SettingsMismatchError
from ogm_ppl.calibration.heldout import TestMap
from ogm_ppl.calibration.leakage import GUIDE_PREFIX
from ogm_ppl.calibration.names import OGM_LABEL, kind_label
from ogm_ppl.metrics import Reliability

__all__ = ["METRICS", "RUN_KEYS", "drop_changed", "load_previous", "row_key", "rows_for", "summary"]

#: the scores of a row that the tables and the summary average over maps
METRICS: tuple[str, ...] = ("nll_bits", "ece", "brier", "auc", "best_f1", "iou")
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
#: what a prior's result holds beyond its scores, copied into each of its rows
_CHAIN_KEYS = ("seconds_per_chain", "patch", "rhat_below", "rhat_below_varying", "rhat_max", "rhat_cells")


def row_key(r: Mapping) -> tuple:
    """``(test, plan, prior_name)``: a row's (map, method) pair, which a resumed run does not compute again."""
    return (r["test"], r["plan"], r["prior_name"])


def rows_for(
    test: str, t: TestMap, name: str, train: str | None, kernel: str, result: Mapping, name_hash: str
) -> list[dict]:
    """The rows (one per mask) of method ``name`` (trained on ``train``, ``None``: nothing) on map ``t`` of the
    test set ``test``: its ``result`` (``{"scores": {mask: ...}, "seconds", ...}``) and digest ``name_hash``."""
    rows = []
    for mask, s in result["scores"].items():
        row = {
            "test": test,
            "train": train or "none",
            "plan": t.name,
            "prior": "ogm" if name == OGM_LABEL else "guide" if name.startswith(GUIDE_PREFIX) else kind_label(name),
            "prior_name": name,
            "kernel": kernel,
            "digest": name_hash,
            "mask": mask,
            **{k: v for k, v in s.items()},
            "seconds": result["seconds"],
        }
        for k in _CHAIN_KEYS:
            if k in result:
                row[k] = result[k]
        rows.append(row)
    return rows


def load_previous(path: Path, settings: Mapping, fresh: bool) -> tuple[list[dict], list[dict]]:
    """The rows and the runs (provenance and seconds of each earlier call) of ``path``, if it exists, is not
    to be ignored (``fresh``) and shares :data:`RUN_KEYS` with ``settings``. Raises
    :class:`~ogm_ppl.calibration.errors.ResultFileError` for a file that is not a calibration result and
    :class:`~ogm_ppl.calibration.errors.SettingsMismatchError` for one of other settings."""
    if fresh or not path.is_file():
        return [], []
    try:
        doc = json.loads(path.read_text())
        rows, old = doc["rows"], doc["settings"]
        runs = doc.get("runs", [])
    except (OSError, ValueError, KeyError, TypeError) as e:
        raise ResultFileError(f"{path}: not a calibration result ({type(e).__name__}: {e}); use --fresh") from None
    differ = [k for k in RUN_KEYS if old.get(k) != settings.get(k)]
    if differ:
        raise SettingsMismatchError(str(path), differ)
    return rows, runs


def drop_changed(rows: list[dict], digests: Mapping[str, str], progress: bool = True) -> list[dict]:
    """``rows`` without those of a name in ``digests`` (the names this run scores) whose recorded digest differs
    from the current one (:func:`~ogm_ppl.calibration.names.name_digest`; a row without one too): they are
    computed again. With ``progress``, one line per such name says so."""
    keep: list[dict] = []
    changed: dict[str, int] = {}
    for r in rows:
        now = digests.get(r["prior_name"])
        if now is not None and r.get("digest") != now:
            changed[r["prior_name"]] = changed.get(r["prior_name"], 0) + 1
        else:
            keep.append(r)
    if progress:
        for name, n in changed.items():
            print(f"{name}: changed since {n} earlier row(s) were computed; computing them again", flush=True)
    return keep


def _mean(rows: list[dict], key: str) -> float:
    v = [r[key] for r in rows if r.get(key) is not None and not (isinstance(r[key], float) and math.isnan(r[key]))]
    return float(np.mean(v)) if v else float("nan")


def _spread(rows: list[dict], key: str) -> dict:
    """``sd`` (population standard deviation), ``min`` and ``max`` of ``key`` over the maps (NaNs left out)."""
    v = [r[key] for r in rows if r.get(key) is not None and not (isinstance(r[key], float) and math.isnan(r[key]))]
    if not v:
        return {"sd": float("nan"), "min": float("nan"), "max": float("nan")}
    return {"sd": float(np.std(v)), "min": float(np.min(v)), "max": float(np.max(v))}


def summary(rows: list[dict]) -> list[dict]:
    """Means over maps per (test, train, prior name, mask): the tables' and the figures' numbers (the
    :data:`METRICS`, seconds and R-hat share, NaNs left out), their spread over the maps (``spread[metric]``:
    ``sd``, ``min``, ``max``), with the reliability diagram pooled over the maps and its ECE (``ece_pooled``)."""
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
                "spread": {k: _spread(g, k) for k in METRICS},
                "ece_pooled": rel.ece,
                "reliability": rel.to_dict(),
            }
        )
    return out
