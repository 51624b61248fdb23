r"""Raster-to-Vector annotations of real Japanese homes: ``r2v`` (1,279 plans, walls and openings as lines in
pixels of images that are not shared; Liu et al., ICCV 2017).

Source: ``r2v-lifull/floorplan_representation/<h1>/<h2>/<listing>/<NNNN>.txt``, one listing (a home) per folder.
A plan's name is that path without ``.txt`` (``03/b1/679c72ca802a4390dc1b2d60f792/0004``); its building is the
listing (``03/b1/679c72ca802a4390dc1b2d60f792``). Each line is ``x1 y1 x2 y2 category a b`` (tab-separated):
``wall`` (a centre line, no thickness), ``door`` (any opening: doors, sliding doors, balcony doors, maybe
windows; lying on a wall), icons (``toilet``, ``bathtub``, ``washing_basin``, ... boxes), room labels (a box
inside the room) and ``point``.

Scale. The coordinates are pixels of images of unknown scale, so the scale is estimated per plan from its
openings (:func:`estimate_scale`): the 25th percentile of the lengths of its openings (``p25``, pixels; openings
under 2 px left out) is taken to be :data:`NOMINAL_OPENING` = 0.75 m, the width of a Japanese interior door (the
smaller, most common openings; the larger ones are sliding doors and balcony openings of 0.9-3.6 m, which is why
the median opening is not used). A plan without an opening is scaled by its fixtures instead (:data:`FIXTURES`:
the long side of a toilet 0.80 m, a bathtub 1.30 m, a washing basin 0.68 m, the sizes the openings' scale gives
them across the corpus); one with neither (one plan of the corpus) by the corpus's median scale,
:data:`CORPUS_SCALE`. The estimates range over 0.011-0.034 m/px (10th-90th percentile; median 0.0226).

How wrong it can be. The corpus has no metric truth, so the estimate was checked against the fixtures, whose real
sizes vary little: on the 1,178 plans with openings, a toilet and a bathtub, the log-ratios of the three
independent scale cues (openings' p25, toilet, bathtub) have standard deviations 0.20 (openings/toilet), 0.19
(openings/bathtub) and 0.19 (toilet/bathtub); splitting their variances (three-cornered hat) leaves 0.14 for the
openings' estimate alone: a plan's scale is typically within 14 % (one standard deviation; 0.13 by the median
absolute deviation, so about 25 % at the 90th percentile). p20 to p35 did as well (0.14-0.15); the median
opening was worse (0.23), the smallest opening much worse (0.37). The absolute level rests on the nominal 0.75 m:
with it, the corpus's median toilet is 0.80 m long and its median bathtub 1.30 m, both usual sizes
(:func:`scale_consistency` measures all this; ``ogm-ppl corpus-stats r2v`` reports it). Against a nominal
width distribution instead (:func:`simulate_openings`: interior doors 0.75 +- 0.05 m, entrance and sliding doors
0.90 +- 0.08 m, balcony openings 1.70 +- 0.25 m, 60/25/15 %, 3-19 openings a plan) the estimate is off by 6 %
(standard deviation of the log-ratio; 7 % at the 90th percentile): the corpus's openings vary more than that.

Rasterisation (:func:`plan_cells`): walls drawn :data:`WALL_THICKNESS` = 0.15 m thick (3 cells at 0.05 m) on
their centre lines, extended at the ends so corners close; the rooms are the cells the walls (openings closed)
enclose, 4-connected (the README's flood fill, from every enclosed region rather than from the label boxes,
which lie inside the rooms); then the openings between two rooms are cut (the cells under them of the walls they
lie on free); an opening onto the outside (a window, the entrance) stays closed. Cells outside the outer wall
loop are unknown; icons (furniture, fixtures) are not drawn. 99.6 % of the room labels (balconies aside) fall in
an enclosed room.

Split: the paper's lists (``splits_at_commit_621fe98/{train,val,test}.txt``; a listing in several lists takes the
most held-out one: test, then val, so the 10 plans listed in both train and test are test plans); a listing in
no list (474 plans) is split by the hash of the listing (``sha256("r2v:<listing>")``, about 1 in 5 test).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np

from ogm_ppl.datasets.floorplans._core import (
    PlanFormatError,
    corpus_path,
    floorplan_root,
    hash_split,
    natural_key,
)
from ogm_ppl.datasets.floorplans._vector import canvas_around, draw_segments, enclosed, vector_cells

__all__ = [
    "CORPUS_SCALE",
    "FIXTURES",
    "NOMINAL_OPENING",
    "R2VPlan",
    "ScaleEstimate",
    "WALL_THICKNESS",
    "building_of",
    "estimate_scale",
    "list_names",
    "plan_cells",
    "plan_path",
    "read_plan",
    "rooms_found",
    "scale_consistency",
    "simulate_openings",
    "split_of",
    "splits",
]

CORPUS = "r2v"
R2V_DIR = "r2v-lifull"
PLANS_DIR = "floorplan_representation"
SPLITS_DIR = "splits_at_commit_621fe98"
SPLIT_SALT = "r2v"
#: metres taken for the 25th percentile of a plan's opening lengths
NOMINAL_OPENING = 0.75
#: openings shorter than this (pixels) are annotation slips, not openings
MIN_OPENING_PX = 2.0
#: quantile of the opening lengths that :data:`NOMINAL_OPENING` is
OPENING_QUANTILE = 25
#: metres of the long side of a fixture's icon, for a plan without openings
FIXTURES: dict[str, float] = {"toilet": 0.80, "bathtub": 1.30, "washing_basin": 0.68}
#: metres per pixel of a plan with neither openings nor fixtures: the median of the corpus's estimates (one plan)
CORPUS_SCALE = 0.0226
#: wall thickness drawn (metres)
WALL_THICKNESS = 0.15
#: room labels (boxes inside rooms)
ROOMS = frozenset(
    ("bedroom", "bathroom", "kitchen", "living_room", "restroom", "balcony", "corridor", "washing_room", "PS")
)
#: the lists, most held-out first: a listing in several takes the first
_SPLIT_ORDER = ("test", "val", "train")


@dataclass(frozen=True)
class R2VPlan:
    """One annotation file: ``walls``, ``openings`` (``K x 4`` pixels ``x1 y1 x2 y2``), ``rooms`` and ``icons``
    (``(category, (x1, y1, x2, y2))`` boxes)."""

    walls: np.ndarray
    openings: np.ndarray
    rooms: tuple[tuple[str, tuple[float, ...]], ...]
    icons: tuple[tuple[str, tuple[float, ...]], ...]


@dataclass(frozen=True)
class ScaleEstimate:
    """A plan's scale: ``metres_per_px``, from ``source`` (``"openings"``, ``"fixtures"`` or ``"corpus"``), ``n``
    the openings (or fixture kinds) it rests on and ``reference_px`` the openings' 25th percentile (pixels)."""

    metres_per_px: float
    source: str
    n: int
    reference_px: float


def _base(root=None) -> Path:
    return corpus_path(floorplan_root(root) / R2V_DIR / PLANS_DIR, CORPUS)


def list_names(root=None) -> list[str]:
    """Every plan name (``h1/h2/listing/NNNN``), in natural order."""
    base = _base(root)
    return sorted((p.relative_to(base).with_suffix("").as_posix() for p in base.glob("*/*/*/*.txt")), key=natural_key)


def plan_path(name: str, root=None) -> Path:
    """The annotation file of a plan (``KeyError`` when there is none)."""
    path = _base(root) / f"{name}.txt"
    if ".." in Path(name).parts or not path.is_file():
        raise KeyError(f"no {CORPUS} plan {name!r} under {_base(root)}")
    return path


def building_of(name: str) -> str:
    """The listing (a home) of a plan: its name without the image number."""
    return name.rsplit("/", 1)[0]


@lru_cache(maxsize=4)
def _splits(folder: str) -> dict[str, str]:
    out: dict[str, str] = {}
    for split in reversed(_SPLIT_ORDER):  # later (more held-out) lists overwrite earlier ones
        path = Path(folder) / f"{split}.txt"
        if not path.is_file():
            raise PlanFormatError(path, "missing: the corpus's split lists are train.txt, val.txt and test.txt")
        for n, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
            if not line.strip():
                continue
            cols = line.split()
            rel = cols[-1] if cols else ""
            if len(cols) != 2 or not rel.startswith(PLANS_DIR + "/") or not rel.endswith(".txt"):
                raise PlanFormatError(
                    path, f"expected 'IMAGE<TAB>{PLANS_DIR}/.../NNNN.txt', got {line!r}", field="column 2", line=n
                )
            out[building_of(rel[len(PLANS_DIR) + 1 : -4])] = split
    return out


def splits(root=None) -> dict[str, str]:
    """Listing -> ``"train"``, ``"val"`` or ``"test"`` of the paper's lists (a listing in several: the most
    held-out one)."""
    return _splits(str(corpus_path(floorplan_root(root) / R2V_DIR / SPLITS_DIR, CORPUS)))


def split_of(name: str, root=None) -> str:
    """The paper's split of the plan's listing, else the hash split of the listing."""
    b = building_of(name)
    return splits(root).get(b) or hash_split(SPLIT_SALT, b)


def read_plan(path: Path) -> R2VPlan:
    """Parse one annotation file; :class:`PlanFormatError` naming the file, line and field for a line that is not
    ``x1 y1 x2 y2 category ...`` with finite numbers, and for a file without walls."""
    try:
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError as e:
        raise PlanFormatError(path, f"not UTF-8 text ({e.reason} at byte {e.start})") from None
    walls, openings, rooms, icons = [], [], [], []
    for n, line in enumerate(text.splitlines(), 1):
        fields = line.rstrip("\t ").split("\t")
        if not line.strip():
            continue
        if len(fields) < 5:
            raise PlanFormatError(
                path, f"expected x1, y1, x2, y2, category (tab-separated), got {len(fields)} field(s)", line=n
            )
        xy = []
        for name, v in zip(("x1", "y1", "x2", "y2"), fields):
            try:
                c = float(v)
            except ValueError:
                raise PlanFormatError(path, f"{v!r} is not a number", field=name, line=n) from None
            if not math.isfinite(c):
                raise PlanFormatError(path, f"{v!r} is not a finite number", field=name, line=n)
            xy.append(c)
        category = fields[4].strip()
        if category == "wall":
            walls.append(xy)
        elif category == "door":
            openings.append(xy)
        elif category in ROOMS:
            rooms.append((category, tuple(xy)))
        elif category and category != "point":
            icons.append((category, tuple(xy)))
    if not walls:
        raise PlanFormatError(path, "no 'wall' line: not a floor plan")
    return R2VPlan(
        np.asarray(walls, float).reshape(-1, 4), np.asarray(openings, float).reshape(-1, 4), tuple(rooms), tuple(icons)
    )


def _lengths(seg: np.ndarray) -> np.ndarray:
    return np.hypot(seg[:, 2] - seg[:, 0], seg[:, 3] - seg[:, 1])


def estimate_scale(plan: R2VPlan) -> ScaleEstimate:
    """Metres per pixel of a plan (the module docstring): :data:`NOMINAL_OPENING` over the 25th percentile of its
    opening lengths; without openings, the geometric mean over :data:`FIXTURES` of nominal size over the median
    long side of that fixture's icons; with neither, :data:`CORPUS_SCALE`."""
    lengths = _lengths(plan.openings)
    lengths = lengths[lengths >= MIN_OPENING_PX]
    if len(lengths):
        p = float(np.percentile(lengths, OPENING_QUANTILE))
        return ScaleEstimate(NOMINAL_OPENING / p, "openings", len(lengths), p)
    logs = []
    for cat, size in FIXTURES.items():
        sides = [max(abs(b[2] - b[0]), abs(b[3] - b[1])) for c, b in plan.icons if c == cat]
        sides = [s for s in sides if s >= MIN_OPENING_PX]
        if sides:
            logs.append(math.log(size / float(np.median(sides))))
    if not logs:
        return ScaleEstimate(CORPUS_SCALE, "corpus", 0, float("nan"))
    return ScaleEstimate(math.exp(sum(logs) / len(logs)), "fixtures", len(logs), float("nan"))


def simulate_openings(
    rng: np.random.Generator, metres_per_px: float, n: int, widths: Sequence[tuple[float, float, float]] | None = None
) -> np.ndarray:
    """``n`` horizontal openings (``n x 4`` pixels) of a plan at ``metres_per_px``, their widths drawn from a
    nominal distribution: ``widths`` = ``(share, mean, sd)`` metres per kind, default interior doors (0.60,
    0.75, 0.05), entrance and sliding doors (0.25, 0.90, 0.08) and balcony openings (0.15, 1.70, 0.25)."""
    kinds = widths or ((0.60, 0.75, 0.05), (0.25, 0.90, 0.08), (0.15, 1.70, 0.25))
    share = np.asarray([k[0] for k in kinds], float)
    k = rng.choice(len(kinds), size=n, p=share / share.sum())
    w = np.maximum(rng.normal([kinds[i][1] for i in k], [kinds[i][2] for i in k]), 0.3) / metres_per_px
    x = rng.uniform(0, 500, n)
    y = rng.uniform(0, 500, n)
    return np.stack([x, y, x + w, y], axis=1)


def plan_cells(
    plan: R2VPlan, scale: ScaleEstimate, resolution: float, thickness: float, where: str | Path
) -> tuple[np.ndarray, np.ndarray]:
    """``(occupied, free)`` cells (``H x W`` bool; the rest is outside, unknown) of a plan at ``resolution``
    metres per cell, walls ``thickness`` metres thick (the module docstring), with a margin of the wall thickness
    plus two cells around the walls."""
    m = scale.metres_per_px
    walls, openings = plan.walls * m, plan.openings * m
    canvas = canvas_around(walls.reshape(-1, 2), resolution, thickness + 2 * resolution, str(where))
    return vector_cells(canvas, walls, openings, thickness)


def rooms_found(plan: R2VPlan, scale: ScaleEstimate, resolution: float, thickness: float) -> tuple[int, int]:
    """``(labels, inside)``: the plan's room labels other than ``balcony`` and how many of their box centres lie
    in an enclosed (free) region: a label outside one marks a wall loop left open in the annotation."""
    m = scale.metres_per_px
    walls, openings = plan.walls * m, plan.openings * m
    canvas = canvas_around(walls.reshape(-1, 2), resolution, thickness + 2 * resolution, "plan")
    inside = enclosed(
        draw_segments(canvas, walls, thickness, cap=True) | draw_segments(canvas, openings, thickness, cap=True)
    )
    boxes = np.asarray([b for c, b in plan.rooms if c != "balcony"], float).reshape(-1, 4) * m
    centre = canvas.to_cells((boxes[:, :2] + boxes[:, 2:]) / 2)
    c = np.clip(np.rint(centre[:, 0]).astype(int), 0, canvas.shape[1] - 1)
    r = np.clip(np.rint(centre[:, 1]).astype(int), 0, canvas.shape[0] - 1)
    return len(boxes), int(inside[r, c].sum())


def _fixture_side(plan: R2VPlan, category: str) -> float:
    """Median long side (pixels) of the plan's icons of ``category`` (NaN without one)."""
    sides = [max(abs(b[2] - b[0]), abs(b[3] - b[1])) for c, b in plan.icons if c == category]
    sides = [s for s in sides if s >= MIN_OPENING_PX]
    return float(np.median(sides)) if sides else math.nan


def scale_consistency(plans: Sequence[R2VPlan]) -> dict:
    """How far the openings' scale can be off (the module docstring): on the plans scaled by their openings that
    have a toilet and a bathtub, the standard deviations of the log-ratios of the three scale cues (openings,
    toilet, bathtub at their :data:`FIXTURES` sizes), the part of them due to the openings (three-cornered hat;
    plain and from the median absolute deviation) and the fixtures' median sizes under the openings' scale."""
    cues = []
    for plan in plans:
        lengths = _lengths(plan.openings)
        if not (lengths >= MIN_OPENING_PX).any():
            continue
        m = estimate_scale(plan).metres_per_px
        t, b = _fixture_side(plan, "toilet"), _fixture_side(plan, "bathtub")
        if math.isfinite(t) and math.isfinite(b):
            cues.append((math.log(m), math.log(FIXTURES["toilet"] / t), math.log(FIXTURES["bathtub"] / b), t, b))
    if len(cues) < 3:
        return {"plans": len(cues)}
    a = np.asarray(cues)
    ab, ac, bc = a[:, 0] - a[:, 1], a[:, 0] - a[:, 2], a[:, 1] - a[:, 2]

    def mad(x: np.ndarray) -> float:
        return float(1.4826 * np.median(np.abs(x - np.median(x))))

    def own(sd: Callable[[np.ndarray], float]) -> float:
        return math.sqrt(max((sd(ab) ** 2 + sd(ac) ** 2 - sd(bc) ** 2) / 2, 0.0))

    def std(x: np.ndarray) -> float:
        return float(np.std(x))

    return {
        "plans": len(cues),
        "sd_log_openings_vs_toilet": round(std(ab), 4),
        "sd_log_openings_vs_bathtub": round(std(ac), 4),
        "sd_log_toilet_vs_bathtub": round(std(bc), 4),
        "sd_log_openings": round(own(std), 4),
        "sd_log_openings_mad": round(own(mad), 4),
        "median_toilet_m": round(float(np.median(np.exp(a[:, 0]) * a[:, 3])), 3),
        "median_bathtub_m": round(float(np.median(np.exp(a[:, 0]) * a[:, 4])), 3),
    }
