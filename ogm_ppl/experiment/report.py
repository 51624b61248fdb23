"""``metrics.json`` and ``metrics.md`` of an experiment, with repeats of a condition pooled.

Pooling (as the thesis's Table 6.4 pooled its 100 datasets): the true/false positive and false negative
counts of every threshold are summed over the datasets of a condition, and the pooled precision, recall
and F1 come from the sums; the pooled AUC is the mean of the datasets' AUCs (an exact pooled AUC would
need every cell's score in one place).
"""

from __future__ import annotations

import json
import math

import numpy as np

from ogm_ppl.io import atomic_write_text
from ogm_ppl.provenance import provenance

__all__ = ["pool", "markdown", "write_outputs"]


def _pool_block(blocks: list[dict]) -> dict:
    c0 = blocks[0]["curve"]
    thr = np.asarray(c0["thresholds"])
    tp = np.sum([b["curve"]["tp"] for b in blocks], axis=0)
    fp = np.sum([b["curve"]["fp"] for b in blocks], axis=0)
    fn = np.sum([b["curve"]["fn"] for b in blocks], axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        prec = np.where(tp + fp > 0, tp / np.maximum(tp + fp, 1), 1.0)
        rec = np.where(tp + fn > 0, tp / np.maximum(tp + fn, 1), 0.0)
        f1 = np.where(prec + rec > 0, 2 * prec * rec / (prec + rec), 0.0)
    i = int(np.argmax(f1))
    d = {
        "cells": int(sum(b["cells"] for b in blocks)),
        "occupied": int(sum(b["occupied"] for b in blocks)),
        "best_f1": float(f1[i]),
        "threshold": float(thr[i]),
        "precision": float(prec[i]),
        "recall": float(rec[i]),
        "curve": {
            "thresholds": thr.tolist(),
            "precision": prec.tolist(),
            "recall": rec.tolist(),
            "f1": f1.tolist(),
            "tp": tp.tolist(),
            "fp": fp.tolist(),
            "fn": fn.tolist(),
        },
    }
    if all("saturated" in b for b in blocks):
        d["saturated"] = int(sum(b["saturated"] for b in blocks))
    for key in ("auc", "nll_bits", "brier", "ece"):
        if key in blocks[0]:
            vals = [b[key] for b in blocks]
            d[key] = float(np.mean(vals))
    if "max_precision" in blocks[0]:
        has = tp > 0
        d["max_precision"] = float(prec[has].max()) if has.any() else float("nan")
    return d


def pool(scores: list[dict], spec) -> list[dict]:
    """One record per condition x algorithm (conditions in spec order)."""
    out = []
    conditions = list(dict.fromkeys(d.condition for d in spec.datasets))
    frac = {d.condition: d.measurement_fraction for d in spec.datasets}
    entry = {d.condition: d.entry for d in spec.datasets}
    for cond in conditions:
        for alg in spec.algorithms:
            recs = [s for s in scores if s["condition"] == cond and s["algorithm"] == alg.name]
            if not recs:
                continue
            r = {
                "condition": cond,
                "entry": entry[cond],
                "algorithm": alg.name,
                "measurement_fraction": frac[cond],
                "datasets": [s["dataset"] for s in recs],
                "mask": _pool_block([s["mask"] for s in recs]),
            }
            if all("touched" in s for s in recs):
                r["touched"] = _pool_block([s["touched"] for s in recs])
            out.append(r)
    return out


def _f(x, nd=4):
    return "–" if x is None or (isinstance(x, float) and math.isnan(x)) else f"{x:.{nd}f}"


def markdown(result) -> str:
    spec = result.spec
    lines = [f"# {spec.name}", ""]
    if spec.description:
        lines += [spec.description, ""]
    mask_desc = {
        "all": "all cells",
        "known": "the cells the map knows (a plan's walls and free space)",
        "near_mapped": f"cells within {spec.metrics.near_mapped_distance:g} cells of a mapped cell",
    }
    lines += [
        "Best F1 over thresholds, precision and recall at that threshold, ROC AUC; *touched*: only cells the",
        "dataset's readings reached. Repeats of a condition (map / noise seeds) are pooled by summing counts.",
        "",
    ]
    sec: dict[str, list[float]] = {}
    for r in result.runs:
        sec.setdefault(r["algorithm"], []).append(r["seconds"])
    for cond in dict.fromkeys(p["condition"] for p in result.pooled):
        rows = [p for p in result.pooled if p["condition"] == cond]
        kind = next(d.kind for d in spec.datasets if d.condition == cond)
        n = len(rows[0]["datasets"])
        lines += [
            f"## {cond} ({n} dataset{'s' if n > 1 else ''}, {100 * rows[0]['measurement_fraction']:.3g} % of the "
            f"readings; mask: {mask_desc[spec.metrics.mask_for(kind)]})",
            "",
        ]
        head = (
            "| algorithm | best F1 | threshold | precision | recall | AUC | max precision | touched F1 | touched AUC |"
        )
        lines += [head, "|---" * 9 + "|"]
        for p in rows:
            m, t = p["mask"], p.get("touched", {})
            lines.append(
                f"| {p['algorithm']} | {_f(m['best_f1'])} | {m['threshold']:.2f} | {_f(m['precision'])} | "
                f"{_f(m['recall'])} | {_f(m.get('auc'))} | {_f(m.get('max_precision'))} | "
                f"{_f(t.get('best_f1'))} | {_f(t.get('auc'))} |"
            )
        sat = [
            (p["algorithm"], p["mask"]["saturated"] / p["mask"]["cells"])
            for p in rows
            if p["mask"].get("saturated") is not None and p["mask"]["cells"]
        ]
        if sat:
            lines += [
                "",
                "Saturated marginals (within 1e-6 of 0 or 1) on the mask: "
                + ", ".join(f"{a} {100 * v:.1f} %" for a, v in sat)
                + ". Where most cells are saturated a map is near-binary: its F1 / AUC say little about calibration.",
            ]
        ds0 = next(d for d in spec.datasets if d.condition == cond)
        b = ds0.params.get("benchmark")
        if ds0.kind in ("log", "bag") and b:
            unseen = "occupied" if b["prior"] > b["threshold"] else "free"
            lines += [
                "",
                f"Benchmark: traditional OGM ({b['delta']}) from all readings, occupied where p > {b['threshold']:g}. "
                f"Cells no reading reached keep the prior p = {b['prior']:g} and so count as *{unseen}* in it "
                "(the thesis's rule); the near-mapped mask holds such cells next to mapped ones.",
            ]
        lines.append("")
    if sec:
        lines += [
            "## Run time (seconds per run task, mean over datasets and chains: ray cast, model and sampling; the "
            "anytime-F1 figures count sampling alone; untimed warm-up compiles the kernels)",
            "",
            "| algorithm | mean s | runs |",
            "|---|---|---|",
        ]
        for a, v in sec.items():
            lines.append(f"| {a} | {np.mean(v):.2f} | {len(v)} |")
        lines.append("")
    if result.failed:
        lines += ["## Failed tasks", ""] + [f"- `{k}`: {v}" for k, v in result.failed.items()] + [""]
    prov = result.provenance
    if prov:
        m = prov["machine"]
        lines += [
            f"Produced by `{prov['command']}` at commit {prov['commit']} (ogm_ppl {prov['ogm_ppl']}) on "
            f"{m['cpu']} ({m['cores']} cores; Python {m['python']}, torch {m['torch']}, numba {m['numba']}), "
            f"{prov['date']}.",
            "",
        ]
    return "\n".join(lines)


def _strip(rec: dict) -> dict:
    return {k: v for k, v in rec.items() if k != "hash"}


def write_outputs(result, tasks, recs: dict) -> None:
    """Fill ``result`` from the task records and write ``metrics.json``, ``metrics.md`` and figures."""
    spec, out = result.spec, result.out_dir
    result.datasets = [_strip(recs[t.id]) for t in tasks if t.kind == "dataset" and t.id in recs]
    result.runs = [_strip(recs[t.id]) for t in tasks if t.kind == "run" and t.id in recs]
    result.scores = [_strip(recs[t.id]) for t in tasks if t.kind == "score" and t.id in recs]
    result.pooled = pool(result.scores, spec)
    result.provenance = provenance()
    doc = {
        "format": "ogm_ppl.experiment.metrics",
        "format_version": 1,
        "provenance": result.provenance,
        "experiment": spec.name,
        "seed": spec.seed,
        "datasets": result.datasets,
        "scores": result.scores,
        "pooled": result.pooled,
        "runs": result.runs,
        "executed": result.executed,
        "skipped": result.skipped,
        "failed": result.failed,
    }
    files = [
        atomic_write_text(out / "metrics.json", json.dumps(doc, indent=1, allow_nan=True)),
        atomic_write_text(out / "metrics.md", markdown(result)),
    ]
    if spec.output.figures and result.scores:
        from ogm_ppl.experiment.figures import write_figures

        files += write_figures(result)
    result.files = files
