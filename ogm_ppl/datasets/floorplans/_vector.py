"""Drawing vector plans (polygons and wall lines in metres) on a grid of cells, with Pillow's polygon fill.

A :class:`Canvas` maps metres to cells: cell ``(r, c)`` covers ``x0 + [c, c + 1) * resolution`` and
``y0 + [r, r + 1) * resolution`` (``y`` grows downwards, as in the sources' image coordinates). Shapes are drawn
with their vertices snapped to the nearest cell centre and filled including their boundary, so

* a filled polygon holds the cells whose centres lie inside it (within half a cell at its edges);
* a wall segment drawn ``width`` metres thick is ``max(1, round(width / resolution))`` cells across (a rectangle
  centred on the segment), extended by half that at both ends so walls meeting at a corner close it;
* an opening cut from a wall is a rectangle along the opening, two cells wider than the wall, not extended; it
  frees the cells of the walls the opening lies on, not of a wall meeting it end-on, and only between two
  inside cells (an opening onto the outside stays closed).

Every shape is one Pillow call (a loop over shapes, never over cells).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ogm_ppl.datasets.floorplans._core import MAX_PLAN_CELLS, PlanFormatError

__all__ = [
    "Canvas",
    "canvas_around",
    "draw_segments",
    "enclosed",
    "exterior",
    "fill_polygons",
    "vector_cells",
    "wall_cells_of",
]


@dataclass(frozen=True)
class Canvas:
    """A grid of ``shape = (rows, cols)`` cells of ``resolution`` metres whose top-left corner is at ``(x0, y0)``
    metres."""

    x0: float
    y0: float
    resolution: float
    shape: tuple[int, int]

    def to_cells(self, xy: np.ndarray) -> np.ndarray:
        """``(..., 2)`` points ``(x, y)`` in metres -> ``(col, row)`` coordinates, integers at cell centres."""
        return (np.asarray(xy, float) - (self.x0, self.y0)) / self.resolution - 0.5

    def image(self):
        """A blank Pillow image of the canvas's size (mode ``L``)."""
        from PIL import Image

        return Image.new("L", (self.shape[1], self.shape[0]), 0)


def canvas_around(xy: np.ndarray, resolution: float, pad: float, where: str) -> Canvas:
    """The canvas holding the points ``xy`` (``N x 2`` metres) with ``pad`` metres around them; a canvas of over
    :data:`~ogm_ppl.datasets.floorplans._core.MAX_PLAN_CELLS` cells is refused (:class:`PlanFormatError` naming
    ``where``): a scale or a coordinate far off."""
    pts = np.asarray(xy, float).reshape(-1, 2)
    lo, hi = pts.min(0) - pad, pts.max(0) + pad
    cols, rows = (math.ceil(float(v)) for v in (hi - lo) / resolution)
    if rows * cols > MAX_PLAN_CELLS:
        size = hi - lo
        raise PlanFormatError(
            where,
            f"the plan spans {size[0]:.1f} m x {size[1]:.1f} m: {rows * cols:,} cells of {resolution} m, over the "
            f"limit of {MAX_PLAN_CELLS:,} (a wrong scale or a stray coordinate?)",
        )
    return Canvas(float(lo[0]), float(lo[1]), float(resolution), (max(rows, 1), max(cols, 1)))


def _draw(canvas: Canvas, shapes: Sequence[np.ndarray]) -> np.ndarray:
    """Fill each ``(k, 2)`` shape given in cell coordinates (vertices snapped to cell centres, boundary included)."""
    from PIL import ImageDraw

    im = canvas.image()
    draw = ImageDraw.Draw(im)
    for s in shapes:
        pts = [(int(c), int(r)) for c, r in np.rint(s).astype(np.int64).tolist()]
        if len(pts) == 1:
            draw.point(pts, fill=1)
        else:
            draw.polygon(pts, fill=1, outline=1)
    return np.asarray(im, dtype=bool)


def fill_polygons(canvas: Canvas, polygons: Sequence[np.ndarray]) -> np.ndarray:
    """``H x W`` bool: the cells inside any of ``polygons`` (each ``k x 2`` metres, ``k >= 3``)."""
    return _draw(canvas, [canvas.to_cells(p) for p in polygons])


def wall_cells_of(width: float, resolution: float) -> int:
    """Cells across a wall drawn ``width`` metres thick: ``max(1, round(width / resolution))``."""
    return max(1, round(width / resolution))


def draw_segments(canvas: Canvas, segments: np.ndarray, width: float, cap: bool) -> np.ndarray:
    """``H x W`` bool: the segments (``K x 4`` metres ``x1 y1 x2 y2``) drawn :func:`wall_cells_of` ``(width)``
    cells thick, as rectangles centred on them; ``cap``: extended by half their thickness at both ends (a
    zero-length segment is then a square), else not (a zero-length segment draws nothing)."""
    seg = np.asarray(segments, float).reshape(-1, 4)
    if not len(seg):
        return np.zeros(canvas.shape, dtype=bool)
    half = (wall_cells_of(width, canvas.resolution) - 1) / 2  # snapped inclusive fill adds the middle cell
    p0, p1 = canvas.to_cells(seg[:, :2]), canvas.to_cells(seg[:, 2:])
    d = p1 - p0
    length = np.hypot(d[:, 0], d[:, 1])
    keep = length > 1e-9
    if not cap:
        p0, p1, d, length = p0[keep], p1[keep], d[keep], length[keep]
        keep = np.ones(len(p0), dtype=bool)
    u = np.where(keep[:, None], d / np.where(keep, length, 1.0)[:, None], [1.0, 0.0])
    n = np.stack([-u[:, 1], u[:, 0]], axis=1) * max(half, 0.0)
    ext = u * (half if cap else 0.0)
    a, b = p0 - ext, p1 + ext
    quads = np.stack([a + n, b + n, b - n, a - n], axis=1)
    return _draw(canvas, list(quads))


def enclosed(barrier: np.ndarray) -> np.ndarray:
    """The cells not in ``barrier`` that no 4-connected path of such cells joins to the grid's edge."""
    from scipy import ndimage

    open_ = ~np.asarray(barrier, bool)
    labels, _ = ndimage.label(open_)
    edge = np.unique(np.concatenate([labels[0], labels[-1], labels[:, 0], labels[:, -1]]))
    return open_ & ~np.isin(labels, edge[edge > 0])


def _carriers(walls: np.ndarray, openings: np.ndarray, thickness: float) -> np.ndarray:
    """``K`` bool: the walls an opening lies on (within 10 degrees of parallel, the opening's middle within
    ``thickness`` of the wall segment)."""
    carry = np.zeros(len(walls), dtype=bool)
    if not len(walls) or not len(openings):
        return carry
    a, d = walls[:, None, :2], (walls[:, 2:] - walls[:, :2])[:, None, :]  # K x 1 x 2
    mid = ((openings[:, :2] + openings[:, 2:]) / 2)[None]  # 1 x D x 2
    od = (openings[:, 2:] - openings[:, :2])[None]
    dd = (d**2).sum(-1)
    t = np.clip(((mid - a) * d).sum(-1) / np.where(dd > 0, dd, 1.0), 0.0, 1.0)
    dist = np.hypot(*(a + t[..., None] * d - mid).transpose(2, 0, 1))
    cross = np.abs(d[..., 0] * od[..., 1] - d[..., 1] * od[..., 0])
    norm = np.sqrt(dd * (od**2).sum(-1))
    parallel = (norm == 0) | (cross <= math.sin(math.radians(10)) * np.where(norm > 0, norm, 1.0))
    return ((dist <= thickness) & parallel).any(axis=1)


def exterior(
    canvas: Canvas, openings: np.ndarray, inside: np.ndarray, barrier: np.ndarray, thickness: float
) -> np.ndarray:
    """``D`` bool: the openings with the outside on one side: a cell at a quarter, half or three quarters of the
    way along, ``thickness / 2`` plus two cells off the opening's line, that is neither ``inside`` nor
    ``barrier``."""
    seg = np.asarray(openings, float).reshape(-1, 4)
    if not len(seg):
        return np.zeros(0, dtype=bool)
    d = seg[:, 2:] - seg[:, :2]
    n = np.stack([-d[:, 1], d[:, 0]], axis=1) / np.maximum(np.hypot(d[:, 0], d[:, 1]), 1e-12)[:, None]
    off = thickness / 2 + 2 * canvas.resolution
    outside = ~inside & ~barrier
    ext = np.zeros(len(seg), dtype=bool)
    for f in (0.25, 0.5, 0.75):
        for sign in (1.0, -1.0):
            c = np.rint(canvas.to_cells(seg[:, :2] + f * d + sign * off * n)).astype(np.int64)
            ok = (c[:, 0] >= 0) & (c[:, 0] < canvas.shape[1]) & (c[:, 1] >= 0) & (c[:, 1] < canvas.shape[0])
            hit = np.ones(len(seg), dtype=bool)  # off the canvas: outside
            hit[ok] = outside[c[ok, 1], c[ok, 0]]
            ext |= hit
    return ext


def vector_cells(
    canvas: Canvas,
    walls: np.ndarray,
    openings: np.ndarray,
    thickness: float,
    inside: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """``(occupied, free)`` cells of a plan drawn from wall segments and openings (``K x 4`` metres each).

    Walls are drawn ``thickness`` metres thick (:func:`draw_segments` with caps). ``inside``: the cells inside the
    building (the rooms' polygons filled); ``None``: the cells the walls, openings closed, enclose
    (:func:`enclosed`). Openings between two inside cells are then cut: the cells under each opening's rectangle
    (two cells wider than the wall) of the walls it lies on (:func:`_carriers`; a wall meeting it end-on stays)
    are free. An opening onto the outside (:func:`exterior`: a window, an entrance) stays closed: the grid is
    the building's inside. The rest (outside) is neither occupied nor free.
    """
    walls = np.asarray(walls, float).reshape(-1, 4)
    openings = np.asarray(openings, float).reshape(-1, 4)
    carry = _carriers(walls, openings, thickness)
    kept = draw_segments(canvas, walls[~carry], thickness, cap=True)
    carrying = draw_segments(canvas, walls[carry], thickness, cap=True)
    barrier = kept | carrying | draw_segments(canvas, openings, thickness, cap=True)
    if inside is None:
        inside = enclosed(barrier)
    openings = openings[~exterior(canvas, openings, inside, barrier, thickness)]
    cut = draw_segments(canvas, openings, thickness + 2 * canvas.resolution, cap=False) & carrying
    occ = (kept | carrying) & ~(cut & ~kept)
    free = (inside | cut) & ~occ
    return occ, free
