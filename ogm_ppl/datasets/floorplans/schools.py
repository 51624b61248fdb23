r"""Floors of real school buildings traced as room polygons: ``schools`` (50 plans, XML; Luperto and Amigoni).

Source: ``schools-luperto/xml/<name>_updated.xml``; a plan's name is the file's stem without ``_updated``
(``Borchen4``). Each file holds ``<scale>`` (``represented_distance`` pixels = ``real_distance`` cm; 90 cm in every
file, 6-31 pixels) and ``<floor><spaces><space>`` per room: ``<bounding_polygon>`` (the room's outline, pixel
coordinates, origin top-left) and ``<space_representation>``, the outline as ``<linesegment>``\ s of class
``WALL`` or ``PORTAL`` (an opening to the space named in ``<portals>``).

Portals. A portal segment has zero length: it marks a point of the door, not its extent. The same portal (one
segment id) appears in both spaces it joins; in 17 of the files the two points lie one door width apart (exactly
the scale's ``represented_distance``: the door was traced end to end), elsewhere they coincide. A door is
therefore the segment between a portal's two points where they lie 0.5-1.5 door widths apart, else
:data:`DOOR_WIDTH` = 0.9 m (the files' own reference distance) centred on each distinct point along the wall it
lies on (the neighbouring ``WALL`` segment of the outline): up to half a door off where the point was an end.

Rasterisation: every room's polygon filled free (a polygon without area, such as Vieilley1's canteen traced as
one point, adds nothing); every ``WALL`` segment drawn :data:`WALL_THICKNESS` = 0.15 m thick (3 cells at 0.05 m)
on top; the doors cut. The cells outside every room are unknown (outside), not wall. Scale: metres per pixel =
``real_distance`` / ``represented_distance`` (units cm, m or mm); a file without one is an error.

Buildings: several files are floors of one school (``Neulengbach1/2``, ``Sabadell1/2/3``, ``Valleceppi_P0/P1``,
``rockislandgroundfloor``/``rockislandsecondfloor``, ``RomainRoland2``/``RomainRolland1``, ...):
:func:`building_of` drops the floor suffix (a trailing number, ``_P<n>``, ``<n>f``, ``ground/first/second floor``)
and the spelling variant. Split by building: ``sha256("schools:<building>")``, about 1 in 5 test.
"""

from __future__ import annotations

import math
import re
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ogm_ppl.datasets.floorplans._core import (
    PlanFormatError,
    corpus_path,
    floorplan_root,
    hash_split,
    natural_key,
)
from ogm_ppl.datasets.floorplans._vector import canvas_around, fill_polygons, vector_cells

__all__ = [
    "DOOR_WIDTH",
    "SchoolPlan",
    "WALL_THICKNESS",
    "building_of",
    "doors",
    "list_names",
    "plan_cells",
    "plan_path",
    "read_plan",
    "split_of",
]

CORPUS = "schools"
XML_DIR = "schools-luperto/xml"
SUFFIX = "_updated.xml"
SPLIT_SALT = "schools"
#: the width of a door (metres) where a portal gives only a point
DOOR_WIDTH = 0.9
#: wall thickness drawn (metres)
WALL_THICKNESS = 0.15
_FLOOR = re.compile(r"(_?p\d+|_?\d+f?|(ground|first|second)floor)$")
_SPELLINGS = {"romainroland": "romainrolland"}
_CM = {"cm": 1.0, "m": 100.0, "mm": 0.1}


@dataclass(frozen=True)
class SchoolPlan:
    """One file: ``metres_per_px``; ``rooms``, ``(space id, label, polygon k x 2 pixels)``; ``walls`` (``K x 4``
    pixels); ``portals``: segment id -> ``[(x1, y1, x2, y2, ux, uy), ...]`` per space listing it (``u``: the unit
    direction of the wall it lies on)."""

    metres_per_px: float
    rooms: tuple[tuple[str, str, np.ndarray], ...]
    walls: np.ndarray
    portals: dict[str, list[tuple[float, ...]]]


def _dir(root=None) -> Path:
    return corpus_path(floorplan_root(root) / XML_DIR, CORPUS)


def list_names(root=None) -> list[str]:
    """Every plan name (the file stems without ``_updated``), in natural order."""
    return sorted((p.name[: -len(SUFFIX)] for p in _dir(root).glob(f"*{SUFFIX}")), key=natural_key)


def plan_path(name: str, root=None) -> Path:
    """The XML file of a plan (``KeyError`` when there is none)."""
    path = _dir(root) / f"{name}{SUFFIX}"
    if "/" in name or not path.is_file():
        raise KeyError(f"no {CORPUS} plan {name!r} under {_dir(root)}")
    return path


def building_of(name: str) -> str:
    """The school a floor belongs to: lower case, without the floor suffix and the spelling variant."""
    b = _FLOOR.sub("", name.lower()).rstrip("_")
    return _SPELLINGS.get(b, b)


def split_of(name: str) -> str:
    """``"train"`` or ``"test"`` by the hash of the plan's building."""
    return hash_split(SPLIT_SALT, building_of(name))


def _number(el: ET.Element | None, path: Path, field: str) -> float:
    text = None if el is None else el.text
    if text is None or not text.strip():
        raise PlanFormatError(path, "missing", field=field)
    try:
        v = float(text)
    except ValueError:
        raise PlanFormatError(path, f"{text.strip()!r} is not a number", field=field) from None
    if not math.isfinite(v) or v <= 0:
        raise PlanFormatError(path, f"must be a positive number, got {text.strip()!r}", field=field)
    return v


def _scale(root: ET.Element, path: Path) -> float:
    sc = root.find("scale")
    if sc is None:
        raise PlanFormatError(path, "missing: no pixel-to-cm scale (<scale><represented_distance>)", field="scale")
    px = _number(sc.find("represented_distance/value"), path, "scale/represented_distance/value")
    real = _number(sc.find("real_distance/value"), path, "scale/real_distance/value")
    unit = (sc.findtext("real_distance/um") or "cm").strip().lower()
    if unit not in _CM:
        raise PlanFormatError(path, f"unit {unit!r} is not one of {', '.join(_CM)}", field="scale/real_distance/um")
    px_unit = (sc.findtext("represented_distance/um") or "pixel").strip().lower()
    if px_unit not in ("pixel", "pixels", "px"):
        raise PlanFormatError(path, f"unit {px_unit!r} is not pixels", field="scale/represented_distance/um")
    return real * _CM[unit] / 100.0 / px


def _points(els: list[ET.Element], path: Path, field: str) -> np.ndarray:
    out = []
    for j, p in enumerate(els):
        xy = []
        for c in ("x", "y"):
            v = p.get(c)
            try:
                f = float(v) if v is not None else math.nan
            except ValueError:
                f = math.nan
            if not math.isfinite(f):
                raise PlanFormatError(path, f"{v!r} is not a number", field=f"{field}/point[{j}]/@{c}")
            xy.append(f)
        out.append(xy)
    return np.asarray(out, float).reshape(-1, 2)


def read_plan(path: Path) -> SchoolPlan:
    """Parse one file; :class:`PlanFormatError` naming the file (and line, for XML syntax) and the field for a
    missing or bad scale, a space without rooms, a polygon of fewer than 3 points, a non-numeric coordinate or a
    segment without 2 points."""
    try:
        root = ET.parse(path).getroot()
    except ET.ParseError as e:
        raise PlanFormatError(path, f"not XML: {e}", line=e.position[0]) from None
    m = _scale(root, path)
    spaces = root.findall("floor/spaces/space")
    if not spaces:
        raise PlanFormatError(path, "no room: expected <floor><spaces><space>", field="floor/spaces")
    rooms, walls = [], []
    portals: dict[str, list[tuple[float, ...]]] = {}
    for k, s in enumerate(spaces):
        sid = s.get("id") or f"#{k}"
        where = f"space[{k}] ({sid})"
        poly = _points(s.findall("bounding_polygon/point"), path, f"{where}/bounding_polygon")
        if len(poly) < 3:
            raise PlanFormatError(
                path, f"a polygon needs at least 3 vertices, got {len(poly)}", field=f"{where}/bounding_polygon"
            )
        rooms.append((sid, (s.findtext("labels/label") or "").strip(), poly))
        segs, kinds, ids = [], [], []
        for j, ls in enumerate(s.findall("space_representation/linesegment")):
            pts = _points(ls.findall("point"), path, f"{where}/linesegment[{j}]")
            if len(pts) != 2:
                raise PlanFormatError(path, f"has {len(pts)} points, not 2", field=f"{where}/linesegment[{j}]")
            segs.append(pts.ravel())
            kinds.append((ls.findtext("class") or "").strip().upper())
            ids.append(ls.get("id") or f"{sid}/{j}")
        for j, (seg, kind) in enumerate(zip(segs, kinds)):
            if kind == "WALL":
                walls.append(seg)
            elif kind == "PORTAL":
                u = _direction(segs, kinds, j)
                portals.setdefault(ids[j], []).append((*seg.tolist(), *u))
    return SchoolPlan(m, tuple(rooms), np.asarray(walls, float).reshape(-1, 4), portals)


def _direction(segs: list[np.ndarray], kinds: list[str], j: int) -> tuple[float, float]:
    """Unit direction of segment ``j`` (a portal), else of the nearest non-degenerate wall before or after it in
    the outline; ``(1, 0)`` when there is none."""
    order = [j] + [i for d in range(1, len(segs)) for i in (j - d, j + d) if 0 <= i < len(segs)]
    for i in order:
        if i != j and kinds[i] != "WALL":
            continue
        d = segs[i][2:] - segs[i][:2]
        n = float(np.hypot(*d))
        if n > 1e-9:
            return float(d[0] / n), float(d[1] / n)
    return 1.0, 0.0


def doors(plan: SchoolPlan) -> np.ndarray:
    """The doors (``D x 4`` pixels) of the plan's portals (the module docstring)."""
    width = DOOR_WIDTH / plan.metres_per_px
    out = []
    for entries in plan.portals.values():
        a = np.asarray(entries, float)
        long = np.hypot(a[:, 2] - a[:, 0], a[:, 3] - a[:, 1]) > 1e-9
        out += [e[:4] for e in a[long]]  # a portal traced with extent is that extent
        pts = np.unique(a[~long][:, :2], axis=0)
        if len(pts) >= 2:
            d = np.hypot(*(pts[:, None, :] - pts[None, :, :]).transpose(2, 0, 1))
            i, k = np.unravel_index(int(np.argmax(d)), d.shape)
            if 0.5 * width <= d[i, k] <= 1.5 * width:
                out.append(np.concatenate([pts[i], pts[k]]))
                continue
        for p in pts:
            u = a[~long][np.all(a[~long][:, :2] == p, axis=1)][0, 4:6]
            out.append(np.concatenate([p - u * width / 2, p + u * width / 2]))
    return np.asarray(out, float).reshape(-1, 4)


def _area(poly: np.ndarray) -> float:
    x, y = poly[:, 0], poly[:, 1]
    return 0.5 * abs(float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1))))


def plan_cells(
    plan: SchoolPlan, resolution: float, thickness: float, where: str | Path
) -> tuple[np.ndarray, np.ndarray]:
    """``(occupied, free)`` cells (``H x W`` bool; the rest is outside, unknown) of a plan at ``resolution``
    metres per cell, walls ``thickness`` metres thick (the module docstring)."""
    m = plan.metres_per_px
    polys = [p * m for _, _, p in plan.rooms if _area(p) > 0]
    walls = plan.walls * m
    pts = np.concatenate([walls.reshape(-1, 2), *polys]) if polys else walls.reshape(-1, 2)
    if not len(pts):
        raise PlanFormatError(where, "no room with an area and no wall: nothing to draw")
    canvas = canvas_around(pts, resolution, thickness + 2 * resolution, str(where))
    inside = fill_polygons(canvas, polys)
    return vector_cells(canvas, walls, doors(plan) * m, thickness, inside=inside)
