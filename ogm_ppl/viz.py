"""Pictures a researcher expects: 2D maps on the thesis colour scale, 1D marginal bars, P-R curves,
reliability diagrams.

The colour scale of Fig. 1.10g runs white -> yellow -> red -> black for ``p = 0 -> 1`` (darker is more
likely occupied); a cell at the prior 0.5 is red-orange. Matplotlib is imported lazily (Agg backend
when no display is set) so that importing :mod:`ogm_ppl` never needs a screen.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

__all__ = [
    "thesis_cmap",
    "plot_map",
    "plot_marginals_1d",
    "plot_first_hit",
    "plot_mutual_information",
    "plot_pr_curve",
    "plot_reliability",
]


def _plt():
    import matplotlib

    if matplotlib.get_backend().lower() not in ("agg", "module://matplotlib_inline.backend_inline"):
        try:
            import os

            if not os.environ.get("DISPLAY"):
                matplotlib.use("Agg")
        except Exception:  # pragma: no cover
            pass
    import matplotlib.pyplot as plt

    return plt


def thesis_cmap():
    """The white-yellow-red-black occupancy colour map of Fig. 1.10g."""
    from matplotlib.colors import LinearSegmentedColormap

    return LinearSegmentedColormap.from_list(
        "ogm_thesis", [(0.0, "white"), (1 / 3, "yellow"), (2 / 3, "red"), (1.0, "black")]
    )


def plot_map(probabilities, grid=None, ax=None, title: str | None = None, poses=None, colorbar=True):
    """Show a 2D occupancy grid (probabilities, shape ``grid.shape`` or ``K``) on the thesis scale.

    NaN cells (e.g. unknown, see :meth:`LogOddsMap.image`) are drawn light grey. Rows grow upwards (y).
    """
    plt = _plt()
    p = np.asarray(probabilities, dtype=float)
    if grid is not None:
        p = p.reshape(grid.shape)
    if ax is None:
        _, ax = plt.subplots(figsize=(4, 4))
    cmap = thesis_cmap().with_extremes(bad="#d9d9d9")
    extent = grid.extent if grid is not None else None
    im = ax.imshow(
        np.ma.masked_invalid(p), cmap=cmap, vmin=0, vmax=1, origin="lower", extent=extent, interpolation="nearest"
    )
    if poses is not None:
        poses = np.atleast_2d(poses)
        ax.plot(poses[:, 0], poses[:, 1], "o", color="tab:blue", ms=5)
    if title:
        ax.set_title(title, fontsize=9)
    ax.set_xticks([])
    ax.set_yticks([])
    if colorbar:
        ax.figure.colorbar(im, ax=ax, fraction=0.046, pad=0.04, label="p(m_k = 1 | z)")
    return ax


def _whole_cell_ticks(axis) -> None:
    """Ticks at whole cells only (an axis of cell indices has no cell 2.5)."""
    from matplotlib.ticker import MaxNLocator

    axis.set_major_locator(MaxNLocator(integer=True))


def plot_marginals_1d(series: Mapping[str, np.ndarray], ax=None, cells=None, title: str | None = None):
    """Grouped bars of 1D marginals ``p(m_k | z)`` for several algorithms (Fig. 2.1 style)."""
    plt = _plt()
    if ax is None:
        _, ax = plt.subplots(figsize=(8, 3))
    names = list(series)
    K = len(next(iter(series.values())))
    k = np.arange(K) if cells is None else np.asarray(cells)
    width = 0.8 / max(len(names), 1)
    for i, name in enumerate(names):
        ax.bar(k + (i - (len(names) - 1) / 2) * width, np.asarray(series[name])[: len(k)], width, label=name)
    ax.set_xlabel("cell k")
    ax.set_ylabel("p(m_k = 1 | z)")
    ax.set_ylim(0, 1)
    _whole_cell_ticks(ax.xaxis)
    ax.legend(fontsize=7, ncol=min(len(names), 3), loc="upper left", framealpha=0.9)
    if title:
        ax.set_title(title, fontsize=9)
    return ax


def plot_first_hit(series: Mapping[str, np.ndarray], ax=None, title: str | None = None):
    """Lines of ``p(f = k | z)`` (Eq. 4.6) for several algorithms (Fig. 4.7 / 5.4 style).

    Each series has one entry per cell of the ray and, optionally, a last entry for "no occupied cell",
    which is not drawn.
    """
    plt = _plt()
    if ax is None:
        _, ax = plt.subplots(figsize=(7, 3))
    for name, p in series.items():
        p = np.asarray(p, dtype=float)
        ax.plot(np.arange(len(p)), p, marker="o", ms=3, label=name)
    ax.set_xlabel("first occupied cell f = k")
    ax.set_ylabel("p(f = k | z)")
    _whole_cell_ticks(ax.xaxis)
    ax.legend(fontsize=7)
    if title:
        ax.set_title(title, fontsize=9)
    return ax


def plot_mutual_information(mi, ax=None, title: str | None = None, cells=None):
    """Heat map of a mutual-information matrix between cells (Fig. 2.9, 5.2); the diagonal (each
    cell's entropy) is masked so that the off-diagonal structure stays visible."""
    plt = _plt()
    mi = np.array(mi, dtype=float)
    np.fill_diagonal(mi, np.nan)
    if ax is None:
        _, ax = plt.subplots(figsize=(4, 3.5))
    ticks = np.arange(mi.shape[0]) if cells is None else np.asarray(cells)
    im = ax.imshow(
        np.ma.masked_invalid(mi),
        cmap="viridis",
        origin="lower",
        extent=(ticks[0] - 0.5, ticks[-1] + 0.5, ticks[0] - 0.5, ticks[-1] + 0.5),
    )
    ax.set_xlabel("cell j")
    ax.set_ylabel("cell k")
    _whole_cell_ticks(ax.xaxis)
    _whole_cell_ticks(ax.yaxis)
    ax.figure.colorbar(im, ax=ax, fraction=0.046, pad=0.04, label="MI (nats)")
    if title:
        ax.set_title(title, fontsize=9)
    return ax


def plot_pr_curve(curves: Mapping[str, tuple[np.ndarray, np.ndarray]], ax=None):
    """Precision-recall curves: ``{name: (recall, precision)}``."""
    plt = _plt()
    if ax is None:
        _, ax = plt.subplots(figsize=(4, 4))
    for name, (rec, prec) in curves.items():
        ax.plot(rec, prec, label=name)
    ax.set_xlabel("recall")
    ax.set_ylabel("precision")
    ax.set_xlim(0, 1)
    ax.set_ylim(0, 1.02)
    ax.legend(fontsize=7)
    return ax


def plot_reliability(diagrams: Mapping, ax=None, title: str | None = None, min_count: int = 1):
    r"""Reliability diagrams: ``{name: Reliability}`` (:func:`ogm_ppl.metrics.reliability`), each the occupied
    share ``O_b / n_b`` of its bins against their mean probability ``S_b / n_b`` (bins holding fewer than
    ``min_count`` cells left out), over the diagonal of perfect calibration; the legend gives each ECE.
    With one diagram the share of cells per bin is drawn as grey bars (right axis)."""
    plt = _plt()
    if ax is None:
        _, ax = plt.subplots(figsize=(4, 4))
    ax.plot([0, 1], [0, 1], color="0.6", lw=0.8, ls="--")
    for name, rel in diagrams.items():
        keep = rel.count >= max(1, int(min_count))
        ax.plot(rel.mean_q[keep], rel.occupied[keep], marker="o", ms=3, lw=1, label=f"{name} (ECE {rel.ece:.3f})")
    if len(diagrams) == 1:
        (rel,) = diagrams.values()
        share = rel.count / max(int(rel.count.sum()), 1)
        twin = ax.twinx()
        twin.bar(rel.edges[:-1], share, width=np.diff(rel.edges), align="edge", color="0.85", zorder=0)
        twin.set_ylim(0, 1)
        twin.set_ylabel("share of cells", fontsize=8)
        ax.set_zorder(twin.get_zorder() + 1)
        ax.patch.set_visible(False)
    ax.set_xlabel("predicted P(occupied)")
    ax.set_ylabel("occupied share")
    ax.set_xlim(0, 1)
    ax.set_ylim(0, 1)
    ax.legend(fontsize=6, loc="upper left")
    if title:
        ax.set_title(title, fontsize=9)
    return ax
