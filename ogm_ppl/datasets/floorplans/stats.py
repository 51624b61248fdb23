r"""Statistics of a floor-plan corpus as rasterised here, and a figure of plans beside their sources.

:func:`corpus_stats` counts, without rasterising, the plans and buildings of each split, and then rasterises the
plans asked for (all by default; ``split``, ``limit`` or ``names`` choose fewer) with the exterior left unknown
(``outside="unknown"``, so that ``known_share`` says how much of each grid is building) and reports:

* ``cells``, ``known_share`` (known / cells) and ``occupied_share`` (occupied / known), pooled over the plans and as
  per-plan percentiles;
* ``wall_thickness_cells``: the lengths of the runs of occupied cells with free cells at both ends, along rows and
  columns (interior walls crossed square-on; a wall met at a slant or a door's end counts longer), as a
  histogram and percentiles; for the corpora whose walls are drawn, the thickness drawn;
* the plans' sizes in metres; for ``r2v`` the scales estimated
  (:func:`~ogm_ppl.datasets.floorplans.r2v.estimate_scale`), their cross-check against the fixtures
  (:func:`~ogm_ppl.datasets.floorplans.r2v.scale_consistency`) and the share of room labels that fell inside an
  enclosed room.

:func:`plan_figure` draws a few plans, each source (image, polygon or lines, in metres) beside its grid.
``ogm-ppl corpus-stats NAME`` (:mod:`ogm_ppl.cli.corpus_stats`) writes both.
"""

from __future__ import annotations

import io
import math
import os
import time
from collections import Counter
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

from ogm_ppl.datasets import floorplans as fp
from ogm_ppl.datasets.floorplans import houseexpo_full, r2v, schools

__all__ = ["corpus_stats", "plan_figure", "wall_runs"]

#: wall runs longer than this are pooled in the histogram's last bin
MAX_RUN = 40


def wall_runs(occupancy: np.ndarray, known: np.ndarray) -> np.ndarray:
    """Lengths (cells) of the runs of known occupied cells that have a known free cell at both ends, along the rows
    and the columns of a grid (``H x W`` bool each): the thickness of walls between free cells."""
    code = np.where(known, np.where(occupancy, 2, 1), 0).astype(np.int8)
    out = []
    for a in (code, code.T):
        padded = np.pad(a, ((0, 0), (1, 1)))  # unknown at both ends of each line: no run wraps
        flat = padded.ravel()
        occ = np.concatenate([[False], flat == 2, [False]])
        edges = np.flatnonzero(np.diff(occ.astype(np.int8)))
        starts, ends = edges[::2], edges[1::2]  # run = flat[starts:ends]
        both = (flat[starts - 1] == 1) & (flat[ends] == 1)
        out.append((ends - starts)[both])
    return np.concatenate(out)


def _pct(values: Sequence[float] | np.ndarray, qs=(10, 50, 90)) -> dict[str, float] | None:
    v = np.asarray(values, float)
    v = v[np.isfinite(v)]
    if not len(v):
        return None
    return {f"p{q}": round(float(np.percentile(v, q)), 4) for q in qs}


def _split_counts(corpus: str, root) -> dict[str, dict[str, int]]:
    names = fp.list_plans(corpus, root)
    plans: Counter[str] = Counter()
    buildings: dict[str, set[str]] = {}
    for n in names:
        s = fp.split_of(corpus, n, root)
        plans[s] += 1
        buildings.setdefault(s, set()).add(fp.building_of(corpus, n))
    return {s: {"plans": plans[s], "buildings": len(buildings[s])} for s in fp.SPLITS if s in plans}


def corpus_stats(
    corpus: str,
    names: Sequence[str] | None = None,
    *,
    split: str | None = None,
    limit: int | None = None,
    resolution: float | str | None = "default",
    root: str | os.PathLike | None = None,
    progress: Callable[[str], None] | None = None,
) -> dict:
    """Statistics of ``corpus`` (the module docstring) as a JSON-able dict.

    Args:
        names: the plans to rasterise (default: every plan, or those of ``split``), then the first ``limit``.
        resolution: metres per cell (``"default"``: the corpus's, 0.05 m).
        progress: called with a line every 500 plans.
    """
    t0 = time.perf_counter()
    all_names = fp.list_plans(corpus, root)
    given = names is not None
    if names is None:
        names = [n for n in all_names if split is None or fp.split_of(corpus, n, root) == split]
    names = list(names)[: None if limit is None else int(limit)]
    res = fp.DEFAULT_RESOLUTION[corpus] if resolution == "default" else resolution
    res = None if res is None else float(res)
    cells = known = occupied = 0
    occ_share, known_share, widths, heights = [], [], [], []
    runs = np.zeros(MAX_RUN + 1, np.int64)
    t_read = time.perf_counter()
    for i, p in enumerate(fp.iter_plans(corpus, names, res, outside="unknown", root=root)):
        cells += p.occupancy.size
        k = int(p.known.sum())
        o = int((p.occupancy & p.known).sum())
        known, occupied = known + k, occupied + o
        occ_share.append(o / k if k else math.nan)
        known_share.append(k / p.occupancy.size)
        scale = 1.0 if p.resolution is None else p.resolution
        heights.append(p.shape[0] * scale)
        widths.append(p.shape[1] * scale)
        runs += np.bincount(np.minimum(wall_runs(p.occupancy, p.known), MAX_RUN), minlength=MAX_RUN + 1)
        if progress is not None and (i + 1) % 500 == 0:
            progress(f"  {corpus}: {i + 1}/{len(names)} plans, {time.perf_counter() - t_read:.0f} s")
    seconds = time.perf_counter() - t_read
    lengths = np.repeat(np.arange(MAX_RUN + 1), runs)
    out: dict = {
        "corpus": corpus,
        "resolution_m": res,
        "outside": "unknown",
        "margin_cells": 20,
        "split_rule": fp.split_rule(corpus),
        "splits": _split_counts(corpus, root),
        "plans_in_corpus": len(all_names),
        "buildings_in_corpus": len({fp.building_of(corpus, n) for n in all_names}),
        "plans": len(names),
        "selection": {"split": split, "limit": limit, "given_names": given},
        "buildings": len({fp.building_of(corpus, n) for n in names}),
        "cells": cells,
        "known_share": known / cells if cells else None,
        "occupied_share": occupied / known if known else None,
        "per_plan": {"occupied_share": _pct(occ_share), "known_share": _pct(known_share)},
        "size": {"unit": "cells" if res is None else "m", "width": _pct(widths), "height": _pct(heights)},
        "wall_thickness_cells": {
            "runs": int(runs.sum()),
            "percentiles": _pct(lengths, (10, 25, 50, 75, 90)),
            "histogram": runs[1:].tolist(),
            "histogram_note": f"runs of 1..{MAX_RUN} cells (the last bin: {MAX_RUN} or more)",
        },
        "seconds_rasterising": round(seconds, 2),
        "seconds_per_plan": round(seconds / max(len(names), 1), 4),
    }
    if corpus in fp.WALL_THICKNESS and res is not None:
        t = fp.WALL_THICKNESS[corpus]
        out["wall_thickness_drawn"] = {"metres": t, "cells": max(1, round(t / res))}
    if corpus == "houseexpo-full":
        out["wall_thickness_drawn"] = {"exterior_cells": 2, "interior": "the polygon's gaps (10-12 cm)"}
    if corpus == "r2v" and res is not None:
        out["r2v"] = _r2v_extra(names, res, root)
    out["seconds"] = round(time.perf_counter() - t0, 2)
    return out


def _r2v_extra(names: Sequence[str], res: float, root) -> dict:
    plans, scales, labels, inside = [], [], 0, 0
    for n in names:
        plan = r2v.read_plan(r2v.plan_path(n, root))
        s = r2v.estimate_scale(plan)
        plans.append(plan)
        scales.append(s)
        a, b = r2v.rooms_found(plan, s, res, r2v.WALL_THICKNESS)
        labels, inside = labels + a, inside + b
    return {
        "scale_m_per_px": _pct([s.metres_per_px for s in scales], (1, 10, 50, 90, 99)),
        "opening_p25_px": _pct([s.reference_px for s in scales], (1, 10, 50, 90, 99)),
        "scale_sources": dict(Counter(s.source for s in scales)),
        "scale_consistency": r2v.scale_consistency(plans),
        "room_labels": labels,
        "room_labels_inside_share": inside / labels if labels else None,
    }


# -- the figure --------------------------------------------------------------------------------------------------
def _draw_source(ax, corpus: str, name: str, root) -> str:
    """Draw a plan's source on ``ax`` (metres where the corpus has them); returns a caption."""
    if corpus in ("houseexpo", "ipa"):
        from PIL import Image

        with Image.open(fp.plan_image_path(corpus, name, root)) as im:
            ax.imshow(np.asarray(im.convert("L")), cmap="gray", interpolation="nearest")
        return "source image (pixels)"
    if corpus == "dungeon":
        from ogm_ppl.datasets.floorplans.images import dungeon_bytes, open_image

        data, where = dungeon_bytes([name], root)[name]
        ax.imshow(np.asarray(open_image(data, where).convert("RGB")), interpolation="nearest")
        return "source image (pixels)"
    if corpus == "houseexpo-full":
        _, verts = next(houseexpo_full.records([name], root))
        v = np.vstack([verts, verts[:1]])
        ax.fill(v[:, 0], v[:, 1], color="0.85")
        ax.plot(v[:, 0], v[:, 1], "k-", lw=0.6)
        cap = f"outline polygon, {len(verts)} vertices (m)"
    elif corpus == "r2v":
        plan = r2v.read_plan(r2v.plan_path(name, root))
        s = r2v.estimate_scale(plan)
        m = s.metres_per_px
        for x1, y1, x2, y2 in plan.walls * m:
            ax.plot([x1, x2], [y1, y2], "k-", lw=1)
        for x1, y1, x2, y2 in plan.openings * m:
            ax.plot([x1, x2], [y1, y2], "r-", lw=2)
        for _, (x1, y1, x2, y2) in plan.rooms:
            ax.add_patch(_rect(x1 * m, y1 * m, x2 * m, y2 * m, "tab:blue"))
        cap = f"walls, openings (red), room labels (blue); {1 / m:.1f} px/m from {s.source}"
    else:
        school = schools.read_plan(schools.plan_path(name, root))
        m = school.metres_per_px
        for _, _, poly in school.rooms:
            q = np.vstack([poly, poly[:1]]) * m
            ax.fill(q[:, 0], q[:, 1], color="0.85")
        for x1, y1, x2, y2 in school.walls * m:
            ax.plot([x1, x2], [y1, y2], "k-", lw=0.6)
        for x1, y1, x2, y2 in schools.doors(school) * m:
            ax.plot([x1, x2], [y1, y2], "r-", lw=1.5)
        cap = f"rooms, walls, doors (red); {1 / m:.1f} px/m"
    ax.set_aspect("equal")
    ax.invert_yaxis()
    return cap


def _rect(x1: float, y1: float, x2: float, y2: float, colour: str):
    from matplotlib.patches import Rectangle

    return Rectangle((min(x1, x2), min(y1, y2)), abs(x2 - x1), abs(y2 - y1), fill=False, ec=colour, lw=0.8)


def plan_figure(
    corpus: str,
    names: Sequence[str],
    path: str | os.PathLike,
    resolution: float | str | None = "default",
    root: str | os.PathLike | None = None,
) -> Path:
    """A PNG at ``path`` (written through a temporary file): one row per plan, its source beside its grid (exterior
    unknown: grey; occupied black; free white). Returns ``path``."""
    from matplotlib.figure import Figure

    from ogm_ppl.io import atomic_write_bytes

    names = list(names)
    fig = Figure(figsize=(11, 4.6 * max(len(names), 1)))
    axes = fig.subplots(max(len(names), 1), 2, squeeze=False)
    for row, plan in zip(axes, fp.iter_plans(corpus, names, resolution, outside="unknown", root=root)):
        cap = _draw_source(row[0], corpus, plan.name, root)
        row[0].set_title(f"{plan.name}\n{cap}", fontsize=8)
        grid = np.where(plan.known, np.where(plan.occupancy, 0.0, 1.0), 0.6)
        res = plan.resolution
        extent = None if res is None else (0, plan.shape[1] * res, plan.shape[0] * res, 0)
        row[1].imshow(grid, cmap="gray", vmin=0, vmax=1, interpolation="nearest", extent=extent)
        unit = "cells" if res is None else f"m, {res} m a cell"
        row[1].set_title(f"grid {plan.shape[0]} x {plan.shape[1]} ({unit}), {plan.split}", fontsize=8)
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110)
    return atomic_write_bytes(path, buf.getvalue())
