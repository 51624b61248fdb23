"""The tables and figures of a calibration run (thesis Section 5.2.3): ``calibration.md`` (:func:`tables_md`)
and the reliability diagrams, bar charts and the matrix of every prior on every test corpus (:func:`figures`),
both made of the :func:`~ogm_ppl.calibration.results.summary` rows.

A test corpus's own table shows the methods learned on it, on nothing and priors of one's own
(:func:`shown`); a plan set, which no prior was learned on, shows every method.
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from ogm_ppl.calibration.heldout import TEST_CORPORA
from ogm_ppl.calibration.leakage import GUIDE_SYM
from ogm_ppl.calibration.names import OWN
from ogm_ppl.calibration.results import METRICS
from ogm_ppl.calibration.scenes import MASKS
from ogm_ppl.metrics import Reliability

__all__ = ["bar_labels", "figures", "fmt", "shown", "tables_md"]


def fmt(x: float | None) -> str:
    """``x`` to 3 decimals; ``""`` for ``None`` or NaN."""
    return "" if x is None or (isinstance(x, float) and math.isnan(x)) else f"{x:.3f}"


def shown(s: dict, test: str) -> bool:
    """Whether a summary row goes into ``test``'s own table and figures: the methods learned on that corpus,
    those learned on nothing and priors of one's own (:data:`~ogm_ppl.calibration.names.OWN`); every method on
    a plan set, which no prior was learned on."""
    return test not in TEST_CORPORA or s["train"].removesuffix(GUIDE_SYM) in (test, "none", OWN)


def bar_labels(names: Sequence[str], test: str) -> list[str]:
    """Bar labels: the prior names without ``:<test>``, except where that would make two alike (``independent``,
    the uniform prior, beside ``independent:<test>``, the one learned on the test corpus)."""
    short = [n.replace(f":{test}", "") for n in names]
    return [s if short.count(s) == 1 else n for s, n in zip(short, names)]


def tables_md(summ: list[dict], settings: dict) -> str:
    """``calibration.md``: the settings, then per mask and test set a table of the :data:`METRICS`, R-hat share
    and seconds of the methods :func:`shown` there, then NLL / AUC on the unseen cells of every prior (rows)
    on every test set (columns)."""
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
            sel = [s for s in summ if s["test"] == test and s["mask"] == mask and shown(s, test)]
            if not sel:
                continue
            lines += [
                f"\n**{test}**, {mask} cells ({sel[0]['maps']} maps)\n",
                "| method | " + " | ".join(METRICS) + " | rhat<1.05 | seconds |",
                "|---" * (len(METRICS) + 3) + "|",
            ]
            for s in sel:
                vals = " | ".join(fmt(s[k]) for k in METRICS)
                lines.append(f"| {s['prior_name']} | {vals} | {fmt(s['rhat_below'])} | {s['seconds']:.1f} |")
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
            cells.append(f"{fmt(hit[0]['nll_bits'])} / {fmt(hit[0]['auc'])}" if hit else "")
        lines.append(f"| {k} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def figures(summ: list[dict], out: Path) -> list[Path]:
    """The figures of a run, written to ``out`` (returned in this order): ``reliability_<test>.png`` (one
    reliability diagram per method :func:`shown` there, unseen cells pooled over maps, bins of 20 cells or more),
    ``bars_<mask>.png`` (NLL and AUC per test set) and ``matrix_unseen.png`` (NLL on the unseen cells of every
    prior and training corpus on every test set)."""
    from ogm_ppl.viz import _plt, plot_reliability

    plt = _plt()
    paths: list[Path] = []
    tests = list(dict.fromkeys(s["test"] for s in summ))
    for test in tests:
        sel = [s for s in summ if s["test"] == test and s["mask"] == "unseen" and shown(s, test)]
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
            sel = [s for s in summ if s["test"] == test and s["mask"] == mask and shown(s, test)]
            labels = bar_labels([s["prior_name"] for s in sel], test)
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
