"""The outputs of the VI-against-MCMC comparison (:mod:`ogm_ppl.studies.vi_vs_mcmc`): the Markdown table
(:func:`table_md`), the figure of summed KL against wall-clock seconds (:func:`plot`), the headlines
(:func:`headlines`), the JSON of a run and back (:func:`to_json`, :func:`load_results`), and the three files of
a run in a folder (:func:`write_results`, :func:`replot`).
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import asdict
from pathlib import Path
from typing import Any

from ogm_ppl.io import atomic_write, atomic_write_text
from ogm_ppl.studies.vi_vs_mcmc.problems import PROBLEMS_2D
from ogm_ppl.studies.vi_vs_mcmc.records import EPS, TARGET, Record

__all__ = [
    "FILES",
    "TITLES",
    "headlines",
    "load_results",
    "plot",
    "replot",
    "style",
    "table_md",
    "to_json",
    "write_results",
]

#: the files of a run: the results, the table, the figure
FILES: tuple[str, ...] = ("results.json", "table.md", "kl_vs_time.png")

#: each problem's title
TITLES: dict[str, str] = {
    "toy": "1D toy: 20 latent cells, thesis readings, GaussianRange(3.0, 1e-3), uniform prior",
    "walls": "1D wall datasets: F = 75, wall 60, sigma 3, 1..10 readings, uniform prior (means over datasets)",
    **{k: v[0] for k, v in PROBLEMS_2D.items()},
}


def _fmt(x: Any, spec: str = ".2e") -> str:
    if x is None or (isinstance(x, float) and math.isnan(x)):
        return "-"
    return format(x, spec)


def table_md(res: dict) -> str:
    """The run ``res`` (:func:`~ogm_ppl.studies.vi_vs_mcmc.study.run`) as Markdown: its headlines, a table per
    problem (summed KL, seconds, time to :data:`~ogm_ppl.studies.vi_vs_mcmc.records.TARGET`, budget, datasets,
    note per method) and the wall datasets' held-out cross-entropies; ``res["quick"]`` marks a quick run."""
    lines = [
        "# Summed KL to the exact posterior against wall-clock time",
        "",
        f"`{res.get('command') or 'ogm_ppl.studies.vi_vs_mcmc.run'}` (seed {res['seed']}), "
        f"{res['seconds']:.0f} s in all, one thread. Summed KL(exact || q) of the cell marginals over the latent "
        f"cells (estimates clamped to [{EPS:g}, 1 - {EPS:g}]); seconds: wall clock of the method (set-up "
        "included, scoring excluded; one-pass methods timed warm). OGM starts from the prior's lambda "
        "(0.5 for the correlated priors). Anytime methods: their last budget, "
        f'and the first time their curve came within {TARGET} ("t(KL<{TARGET})").',
        "",
    ]
    for h in res.get("headlines", []):
        lines.append(f"* {h}")
    for key, prob in res["problems"].items():
        lines += ["", f"## {key}: {TITLES.get(key, key)}", ""]
        lines += [
            "| method | summed KL | seconds | t(KL<0.01) s | budget | datasets | note |",
            "|---|---:|---:|---:|---:|---:|---|",
        ]
        for r in prob["records"]:
            r = r if isinstance(r, Record) else Record(**r)
            budget = f"{r.curve[-1][0]} {r.unit}" if r.curve else ""
            t_to = None if r.kind == "exact" else r.time_to()
            lines.append(
                f"| {r.method} | {_fmt(r.kl)} | {_fmt(r.seconds, '.3g')} | {_fmt(t_to, '.3g')} | "
                f"{budget} | {r.datasets} | {r.note} |"
            )
        if "heldout" in prob:
            h = prob["heldout"]
            lines += [
                "",
                "### Held-out cross-entropy on the wall datasets (nats per dataset, cells 1..F)",
                "",
                f"Out of fold: {h['folds']}-fold cross-fitting on the {h['datasets']} datasets (seed 0); "
                f"KL = cross-entropy - exact entropy ({h['entropy']:.4f}).",
                "",
                "| update term | held-out cross-entropy (mean +- sd over folds) | summed KL |",
                "|---|---:|---:|",
            ]
            for name, v in h["out_of_fold"].items():
                lines.append(f"| {name} | {v['ce']:.4f} +- {v['ce_sd_folds']:.4f} | {v['kl']:.4f} |")
            f = h["fresh"]
            lines += [
                "",
                f"Shipped artefacts (fitted on all 1000 seed-0 datasets) on {f['datasets']} fresh datasets "
                f"(seed 1; exact entropy {f['entropy']:.4f}):",
                "",
                "| update term | cross-entropy | summed KL |",
                "|---|---:|---:|",
            ]
            for name, v in f.items():
                if isinstance(v, dict):
                    lines.append(f"| {name} | {v['ce']:.4f} | {v['kl']:.4f} |")
    lines += ["", "![KL against time](kl_vs_time.png)", ""]
    return "\n".join(lines)


def headlines(res: dict) -> list[str]:
    """One-sentence findings of a run: the best guide and cell Gibbs on the 1D toy, the out-of-fold
    cross-entropies of the neural update term and p21 on the wall datasets (for the problems run)."""
    out = []
    toy = res["problems"].get("toy")
    if toy:
        vis = [r for r in toy["records"] if r.method.startswith("VI")]
        best = min(vis, key=lambda r: r.kl)
        mf = [r.kl for r in vis if r.method.startswith("VI mean field")]
        t = best.time_to()
        out.append(
            f"1D toy: best guide {best.method}, summed KL {best.kl:.2e} after {best.curve[-1][0]} steps, "
            f"{best.seconds:.2f} s"
            + (f" (within {TARGET} after {t:.2f} s)" if t is not None else "")
            + f"; mean field {min(mf):.2e}..{max(mf):.2e} over its objectives."
        )
        g = next(r for r in toy["records"] if r.method == "Gibbs (cell, heat bath)")
        out.append(
            f"1D toy: cell Gibbs {g.kl:.2e} after {g.curve[-1][0]} sweeps, {g.seconds:.2f} s"
            + (f" (within {TARGET} after {g.time_to():.3f} s)" if g.time_to() is not None else "")
            + "."
        )
    walls = res["problems"].get("walls")
    if walls:
        h = walls["heldout"]["out_of_fold"]
        p, n = h["p21 (refit, out of fold)"], h["neural Delta (refit, out of fold)"]
        out.append(
            f"Wall datasets, held-out cross-entropy (out of fold): neural Delta {n['ce']:.4f} against p21 "
            f"{p['ce']:.4f} (summed KL {n['kl']:.4f} against {p['kl']:.4f})."
        )
    return out


def style(method: str) -> dict:
    """Line and marker of a method: colour by family (VI: by guide), line style by objective."""
    if method.startswith("VI "):
        guide, _, objective = method[3:].partition(", ")
        colour = {"mean": "tab:red", "patch": "tab:purple", "first": "tab:blue"}[guide.split()[0]]
        ls, marker = {"TraceGraph": (":", "x"), "RWS": ("--", "^"), "exact ELBO": ("-", "o")}[objective]
        return dict(color=colour, ls=ls, marker=marker, ms=5, lw=1.4)
    one = dict(ls="none", ms=8)
    if method.startswith("OGM"):
        return dict(one, color="0.25", marker={"H": "o", "p": "s"}.get(method[4], "^"))
    if "patch map" in method or "overlap" in method:
        colour = "tab:orange" if "online" in method else ("saddlebrown" if "overlap" in method else "goldenrod")
        return dict(one, color=colour, marker="D" if ("L=5" in method or "3x3" in method) else "v")
    if method.startswith("amortised"):
        return dict(one, color="magenta", marker="*", ms=12)
    gibbs = {
        "Gibbs (cell, heat bath)": ("tab:green", "o"),
        "Gibbs (cell, metropolised)": ("darkgreen", "s"),
        "guided Gibbs (cell + guide 2x2 blocks)": ("olive", "X"),
    }
    colour, marker = gibbs.get(method, ("teal", "P") if "3x3" in method else ("tab:cyan", "D"))
    return dict(color=colour, ls="-", marker=marker, ms=5, lw=1.6)


def plot(res: dict, path: str | os.PathLike) -> None:
    """The figure of a run: per problem, summed KL against wall-clock seconds (log-log; one-pass methods as
    points, anytime methods as curves, the target and the exact posterior's time as lines), written as a PNG
    to ``path``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names: list[str] = []
    for prob in res["problems"].values():
        for r in prob["records"]:
            if r.kind != "exact" and not math.isnan(r.kl) and r.method not in names:
                names.append(r.method)
    probs = list(res["problems"].items())
    ncol = 3
    nrow = math.ceil((len(probs) + 1) / ncol)
    fig, axes = plt.subplots(nrow, ncol, figsize=(6.0 * ncol, 4.6 * nrow), squeeze=False)
    floor = 1e-6
    for ax, (key, prob) in zip(axes.flat, probs):
        for r in prob["records"]:
            if r.kind == "exact":
                if r.method == "exact":
                    ax.axvline(max(r.seconds, 1e-5), color="0.5", ls=":", lw=1)
                continue
            if math.isnan(r.kl):
                continue
            pts = r.curve or [(0, r.seconds, r.kl)]
            ax.plot([max(p[1], 1e-5) for p in pts], [max(p[2], floor) for p in pts], **style(r.method))
        ax.axhline(TARGET, color="k", lw=0.8, ls="--")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_title(f"{key}: {TITLES.get(key, key)}", fontsize=8.5)
        ax.set_xlabel("seconds (wall clock)")
        ax.set_ylabel("summed KL to exact")
        ax.grid(True, which="major", alpha=0.3)
    for ax in list(axes.flat)[len(probs) :]:
        ax.axis("off")
    handles = [plt.Line2D([], [], **style(n)) for n in names]
    handles += [plt.Line2D([], [], color="k", ls="--", lw=0.8), plt.Line2D([], [], color="0.5", ls=":")]
    labels = [*names, f"KL = {TARGET}", "exact posterior's time"]
    list(axes.flat)[-1].legend(handles, labels, loc="center", fontsize=7.5, frameon=False, ncol=1)
    fig.tight_layout()
    with atomic_write(path) as f:
        fig.savefig(f, format="png", dpi=110)
    plt.close(fig)


def load_results(path: str | os.PathLike) -> dict:
    """``results.json`` back as :func:`~ogm_ppl.studies.vi_vs_mcmc.study.run` returned it (records as
    :class:`~ogm_ppl.studies.vi_vs_mcmc.records.Record`)."""
    res = json.loads(Path(path).read_text())
    for prob in res["problems"].values():
        records = []
        for r in prob["records"]:
            fields: dict[str, Any] = {
                k: (math.nan if v is None and k in ("kl", "seconds") else v)
                for k, v in r.items()
                if k != "time_to_kl_0.01"
            }
            records.append(Record(**fields))
        prob["records"] = records
    return res


def to_json(res: dict) -> str:
    """The run ``res`` as JSON: each :class:`~ogm_ppl.studies.vi_vs_mcmc.records.Record` as its fields and its
    ``time_to_kl_0.01``, NaN as ``null``."""

    def enc(o: Any) -> Any:
        if isinstance(o, Record):
            d = asdict(o)
            d["time_to_kl_0.01"] = o.time_to()
            return {k: None if isinstance(v, float) and math.isnan(v) else v for k, v in d.items()}
        raise TypeError(type(o).__name__)

    return json.dumps(res, indent=1, default=enc, allow_nan=True)


def write_results(res: dict, out: str | os.PathLike) -> str:
    """Write the run ``res`` into the folder ``out`` (created if missing) as :data:`FILES`: ``results.json``
    (:func:`to_json`), ``table.md`` (:func:`table_md`) and ``kl_vs_time.png`` (:func:`plot`); returns the
    table's Markdown."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    atomic_write_text(out / "results.json", to_json(res))
    md = table_md(res)
    atomic_write_text(out / "table.md", md)
    plot(res, out / "kl_vs_time.png")
    return md


def replot(out: str | os.PathLike) -> dict:
    """Redraw ``table.md`` and ``kl_vs_time.png`` in the folder ``out`` from its ``results.json``; returns the run
    (:func:`load_results`)."""
    out = Path(out)
    res = load_results(out / "results.json")
    atomic_write_text(out / "table.md", table_md(res))
    plot(res, out / "kl_vs_time.png")
    return res
