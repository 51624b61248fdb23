"""Figures of an experiment (matplotlib, Agg), written under ``out_dir/figures``:

* ``pr_COND.png`` — precision-recall curves per algorithm, pooled over the condition (Fig. 6.8);
* ``f1_threshold_COND.png`` — F1 against the threshold (Fig. 6.9);
* ``f1_sparsity_ENTRY.png`` — best F1 (and touched-only F1) against the share of readings kept, when an
  entry's datasets differ by sparsity (Fig. 6.17);
* ``fpfn_DATASET.png`` — per algorithm: the map, the map thresholded at its best F1, and the cells that
  differ from the truth (false positives blue, false negatives red; cells outside the mask grey)
  (Fig. 6.6), and ``fpfn_thresholds_DATASET.png`` at fixed thresholds (Fig. 6.7);
* ``f1_time_DATASET.png`` — F1 of the running Gibbs marginals against wall-clock seconds.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ogm_ppl.io import atomic_write

__all__ = ["write_figures"]


def _plt():
    import matplotlib

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    return plt


def _save(fig, path: Path, dpi: int) -> Path:
    with atomic_write(path) as f:
        fig.savefig(f, format="png", dpi=dpi, bbox_inches="tight")
    return path


def _line_plot(ax, xlabel: str, ylabel: str, title: str) -> None:
    """Labels, a small title, legend and grid of the line figures."""
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.set_title(title, fontsize=9)
    ax.legend(fontsize=7)
    ax.grid(alpha=0.3)


def _save_closed(plt, fig, path: Path, dpi: int) -> Path:
    out = _save(fig, path, dpi)
    plt.close(fig)
    return out


def _curves(result, folder: Path, dpi: int) -> list[Path]:
    plt = _plt()
    files = []
    for cond in dict.fromkeys(p["condition"] for p in result.pooled):
        rows = [p for p in result.pooled if p["condition"] == cond]
        fig, ax = plt.subplots(figsize=(5, 4))
        for p in rows:
            c = p["mask"]["curve"]
            ax.plot(
                c["recall"],
                c["precision"],
                label=f"{p['algorithm']} (F1 {p['mask']['best_f1']:.3f})",
            )
        _line_plot(ax, "recall", "precision", f"Precision-recall: {cond}")
        files.append(_save_closed(plt, fig, folder / f"pr_{cond}.png", dpi))
        fig, ax = plt.subplots(figsize=(5, 4))
        for p in rows:
            c = p["mask"]["curve"]
            ax.plot(c["thresholds"], c["f1"], label=p["algorithm"])
        _line_plot(ax, "threshold (cell called occupied when p > threshold)", "F1", f"F1 against threshold: {cond}")
        files.append(_save_closed(plt, fig, folder / f"f1_threshold_{cond}.png", dpi))
    return files


def _sparsity(result, folder: Path, dpi: int) -> list[Path]:
    plt = _plt()
    files = []
    for entry in dict.fromkeys(p["entry"] for p in result.pooled):
        rows = [p for p in result.pooled if p["entry"] == entry]
        fracs = sorted({p["measurement_fraction"] for p in rows})
        if len(fracs) < 2:
            continue
        touched = all("touched" in p for p in rows)
        fig, axes = plt.subplots(1, 2 if touched else 1, figsize=(9 if touched else 5, 4), squeeze=False)
        for alg in dict.fromkeys(p["algorithm"] for p in rows):
            ps = sorted((p for p in rows if p["algorithm"] == alg), key=lambda p: p["measurement_fraction"])
            x = [100 * p["measurement_fraction"] for p in ps]
            axes[0, 0].plot(x, [p["mask"]["best_f1"] for p in ps], "o-", label=alg)
            if touched:
                axes[0, 1].plot(x, [p["touched"]["best_f1"] for p in ps], "o-", label=alg)
        for ax, what in zip(axes[0], ("scoring mask", "touched cells only")):
            ax.set_xscale("log")
            _line_plot(ax, "readings used (% of all)", "best F1", f"{entry}: F1 against sparsity ({what})")
        files.append(_save_closed(plt, fig, folder / f"f1_sparsity_{entry}.png", dpi))
    return files


def _fpfn_image(q, truth, mask, thr):
    called = q > thr
    img = np.ones(q.shape + (3,))
    img[called & ~truth] = (0.12, 0.35, 0.95)  # false positive: blue
    img[~called & truth] = (0.9, 0.1, 0.1)  # false negative: red
    img[~mask] = (0.85, 0.85, 0.85)
    return img


def _fpfn(result, folder: Path, dpi: int) -> list[Path]:
    from ogm_ppl.experiment.tasks import dataset_path, load_eval, score_path
    from ogm_ppl.viz import thesis_cmap

    plt = _plt()
    spec, out = result.spec, result.out_dir
    mode = spec.output.fpfn
    if mode == "none":
        return []
    seen, chosen = set(), []
    for ds in spec.datasets:
        if mode == "all" or ds.condition not in seen:
            chosen.append(ds)
            seen.add(ds.condition)
    by = {(s["dataset"], s["algorithm"]): s for s in result.scores}
    files = []
    for ds in chosen:
        algs = [a for a in spec.algorithms if (ds.name, a.name) in by]
        if not algs:
            continue
        truth, mask, _ = load_eval(out, ds, spec.metrics)
        with np.load(dataset_path(out, ds).with_suffix(".eval.npz")) as z:
            shape = z["truth"].shape
        qs = {}
        for a in algs:
            with np.load(score_path(out, ds, a).with_suffix(".npz")) as z:
                qs[a.name] = z["marginals"].ravel()
        kw = {"origin": "lower", "interpolation": "nearest"}
        fig, axes = plt.subplots(len(algs), 3, figsize=(9, 3 * len(algs)), squeeze=False)
        for i, a in enumerate(algs):
            q, thr = qs[a.name], by[(ds.name, a.name)]["mask"]["threshold"]
            axes[i, 0].imshow(q.reshape(shape), cmap=thesis_cmap(), vmin=0, vmax=1, **kw)
            axes[i, 1].imshow((q > thr).reshape(shape), cmap="gray_r", vmin=0, vmax=1, **kw)
            axes[i, 2].imshow(_fpfn_image(q, truth, mask, thr).reshape(shape + (3,)), **kw)
            axes[i, 0].set_ylabel(a.name, fontsize=8)
            axes[i, 1].set_title(
                f"p > {thr:.2f} (best F1 {by[(ds.name, a.name)]['mask']['best_f1']:.3f})",
                fontsize=8,
            )
            axes[i, 2].set_title("FP blue, FN red", fontsize=8)
        for ax in axes.ravel():
            ax.set_xticks([])
            ax.set_yticks([])
        files.append(_save_closed(plt, fig, folder / f"fpfn_{ds.name}.png", dpi))
        thrs = spec.output.fpfn_thresholds
        if thrs:
            fig, axes = plt.subplots(len(algs), len(thrs), figsize=(3 * len(thrs), 3 * len(algs)), squeeze=False)
            for i, a in enumerate(algs):
                for j, thr in enumerate(thrs):
                    axes[i, j].imshow(_fpfn_image(qs[a.name], truth, mask, thr).reshape(shape + (3,)), **kw)
                    axes[i, j].set_title(f"{a.name}, p > {thr:g}", fontsize=8)
                    axes[i, j].set_xticks([])
                    axes[i, j].set_yticks([])
            files.append(_save_closed(plt, fig, folder / f"fpfn_thresholds_{ds.name}.png", dpi))
    return files


def _time(result, folder: Path, dpi: int) -> list[Path]:
    plt = _plt()
    files = []
    for ds in dict.fromkeys(r["dataset"] for r in result.runs if r.get("trace")):
        fig, ax = plt.subplots(figsize=(5, 4))
        for r in result.runs:
            if r["dataset"] != ds or not r.get("trace"):
                continue
            pts = [t for t in r["trace"] if "f1" in t]
            if pts:
                ax.plot(
                    [t["seconds"] for t in pts],
                    [t["f1"] for t in pts],
                    "o-",
                    ms=3,
                    label=f"{r['algorithm']} c{r['chain']}",
                )
        _line_plot(ax, "wall-clock seconds (sampling)", "best F1 of the running marginals", f"Anytime F1: {ds}")
        files.append(_save_closed(plt, fig, folder / f"f1_time_{ds}.png", dpi))
    return files


def write_figures(result) -> list[Path]:
    """Write every figure that the results allow; returns the paths."""
    folder = Path(result.out_dir) / "figures"
    dpi = result.spec.output.dpi
    return (
        _curves(result, folder, dpi)
        + _sparsity(result, folder, dpi)
        + _fpfn(result, folder, dpi)
        + _time(result, folder, dpi)
    )
