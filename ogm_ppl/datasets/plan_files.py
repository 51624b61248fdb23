r"""Floor plans of any building, read from files: ROS map_server maps, HouseExpo layouts and plain images.

The corpora of :mod:`ogm_ppl.datasets.floorplans` are fixed collections. A plan of a building in none of them
comes as a file, and :func:`load_plan_file` turns it into the same :class:`~ogm_ppl.datasets.floorplans.FloorPlan`
the corpora give (occupancy and known masks, ``H x W`` bool, row 0 at the top of the image), so every
experiment that scores held-out plans can score it (``ogm-ppl calibrate --plan-files``,
:func:`ogm_ppl.calibration.calibrate`).

Three kinds of file:

* ``.yaml`` / ``.yml``: a ROS ``map_server`` map (:func:`ogm_ppl.rosmap.load_ros_map`, Nav2's reading): a cell
  is occupied where map_server publishes 100, free where it publishes 0 and unknown where it publishes -1;
  *scale* mode's values in between count as occupied from 50 up. The map's own ``resolution`` is its pixel
  size. Images a YAML in the same folder names are read through that YAML only.
* ``.json``: a HouseExpo layout (Li et al., IROS 2020; the format of its 35,357 plans, of which the
  ``houseexpo`` corpus here holds 100 renderings): ``verts``, the house's outline as one polygon of ``[x, y]``
  metres, rendered as HouseExpo renders it (``pseudoslam/viz/vis_maps.py``): 1 cm pixels, the vertices
  truncated to whole pixels, the polygon filled free, 25 pixels of exterior around it. Its pixel size is 0.01 m.
* ``.png`` / ``.pgm`` / ``.bmp``: a drawn or scanned plan, dark = occupied, light = free, converted to 8-bit grey
  (16-bit images scaled, not clipped) and classified as the IPA corpus is (the most common grey of the image
  border, when it is neither black nor white, +-3 is unknown; the rest is thresholded at 128); transparent
  pixels are unknown. The outside of the building must be dark, that grey or transparent: a plan drawn on white
  paper reads its surroundings as free space. An image has no scale: ``pixel_size`` (metres per pixel) must be
  given.

Then as every corpus plan (the module docstring of :mod:`~ogm_ppl.datasets.floorplans`, steps 2-5): resampled to
``resolution`` metres per cell (a cell is occupied if any pixel whose top-left corner lies in it is occupied;
a plan coarser than ``resolution`` is repeated, each cell taking the pixel under its centre), cropped to the
free space plus ``margin`` cells, the exterior marked, and unknown cells made occupied (``outside="occupied"``,
the default) or left unknown.

Plans are untrusted input: every problem raises :class:`PlanFileError` naming the file, and a plan whose grid
would exceed :data:`MAX_PLAN_CELLS` cells is refused before it is built.

>>> import numpy as np, tempfile, pathlib
>>> from PIL import Image
>>> px = np.full((40, 40), 255, np.uint8); px[:, :4] = 0                # a wall along the left edge
>>> d = pathlib.Path(tempfile.mkdtemp()); Image.fromarray(px).save(d / "room.png")
>>> plan = load_plan_file(d / "room.png", pixel_size=0.025)            # 2 x 2 pixels a cell at 0.05 m
>>> plan.name, plan.shape, int((~plan.occupancy[30]).sum())           # 36 free pixels -> 18 free cells
('room', (60, 58), 18)
"""

from __future__ import annotations

import hashlib
import math
import os
from collections.abc import Iterable, Sequence
from functools import lru_cache
from pathlib import Path

import numpy as np

from ogm_ppl.datasets import floorplans as fp
from ogm_ppl.datasets.floorplans import FloorPlan, rasterise
from ogm_ppl.datasets.floorplans._core import natural_key as _natural_key
from ogm_ppl.datasets.floorplans.houseexpo_full import (
    HOUSEEXPO_PX_PER_M,
    MAX_LAYOUT_PIXELS,
    layout_pixels,
    layout_size,
)
from ogm_ppl.datasets.floorplans.images import classify_ipa as _classify_ipa
from ogm_ppl.datasets.floorplans.images import open_image as _open_image
from ogm_ppl.datasets.floorplans.images import plan_pixels

__all__ = [
    "PLAN_SUFFIXES",
    "MAX_PLAN_CELLS",
    "PlanFileError",
    "load_plan_file",
    "plan_files",
    "plan_names",
    "render_layout",
    "corpus_copy",
    "plan_file_pieces",
    "NEAR_COPY",
]

IMAGE_SUFFIXES: tuple[str, ...] = (".png", ".pgm", ".bmp")
YAML_SUFFIXES: tuple[str, ...] = (".yaml", ".yml")
LAYOUT_SUFFIXES: tuple[str, ...] = (".json",)
PLAN_SUFFIXES: tuple[str, ...] = YAML_SUFFIXES + LAYOUT_SUFFIXES + IMAGE_SUFFIXES
_MAX_LAYOUT_BYTES = 16 * 2**20
_MAX_LAYOUT_VERTS = 100_000
#: Largest plan grid built (cells, after resampling); a larger one is refused with this limit in the message.
MAX_PLAN_CELLS = 50_000_000


class PlanFileError(ValueError):
    """A plan file is missing, unreadable, malformed or unusable; the message names the path."""

    def __init__(self, path: str | os.PathLike, problem: str):
        self.path, self.problem = str(path), problem
        super().__init__(f"{path}: {problem}")


def _positive(value, what: str, path: Path) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise PlanFileError(path, f"{what} must be a number, got {value!r}") from None
    if not math.isfinite(v) or v <= 0:
        raise PlanFileError(path, f"{what} must be a positive number of metres, got {value!r}")
    return v


def _pixels_of_yaml(path: Path) -> tuple[np.ndarray, np.ndarray, float]:
    from ogm_ppl.rosmap import RosMapError, load_ros_map

    try:
        m = load_ros_map(path)
    except RosMapError as e:
        problem = e.problem if Path(e.path) == path else f"its image {e.path}: {e.problem}"
        raise PlanFileError(path, problem) from None
    rows, cols = m.grid.shape if m.grid.ndim == 2 else (1, m.grid.num_cells)
    v = m.occupancy.reshape(rows, cols)[::-1]  # OccupancyGrid row 0 is the bottom; plans have the top first
    occ = v >= 50
    free = (v >= 0) & (v < 50)
    return occ, free, float(m.settings.resolution)


def _layout_verts(path: Path) -> np.ndarray:
    """The ``verts`` of a HouseExpo layout, ``V x 2`` float metres, validated."""
    import json

    try:
        raw = path.read_bytes()
    except OSError as e:
        raise PlanFileError(path, f"cannot read ({e.strerror or e})") from None
    if len(raw) > _MAX_LAYOUT_BYTES:
        raise PlanFileError(path, f"over {_MAX_LAYOUT_BYTES // 2**20} MiB: not a layout")
    try:
        doc = json.loads(raw.decode("utf-8-sig"))
    except (UnicodeDecodeError, json.JSONDecodeError) as e:
        where = f" (line {e.lineno}, column {e.colno})" if isinstance(e, json.JSONDecodeError) else ""
        raise PlanFileError(path, f"not JSON text{where}: {e}") from None
    if not isinstance(doc, dict) or "verts" not in doc:
        raise PlanFileError(path, "not a HouseExpo layout: no 'verts' (the outline as [[x, y], ...] metres)")
    verts = doc["verts"]
    ok = isinstance(verts, list) and 3 <= len(verts) <= _MAX_LAYOUT_VERTS
    ok = ok and all(
        isinstance(v, list)
        and len(v) == 2
        and all(isinstance(c, (int, float)) and not isinstance(c, bool) and math.isfinite(c) for c in v)
        for v in verts
    )
    if not ok:
        raise PlanFileError(path, f"'verts' must be 3 to {_MAX_LAYOUT_VERTS:,} pairs of finite numbers [x, y]")
    return np.asarray(verts, dtype=np.float64)


def _grey8(im, path: Path):
    """The image as 8-bit grey (``"L"``): 16-bit and 32-bit integer images scaled by ``1/257`` (Pillow's own
    conversion clips them at 255), anything else converted by Pillow; ``(grey, transparent)`` with
    ``transparent`` the pixels of alpha 0 (None without alpha)."""
    from PIL import Image

    transparent = None
    if im.mode in ("RGBA", "LA", "PA") or (im.mode == "P" and "transparency" in im.info):
        transparent = np.asarray(im.convert("RGBA"))[..., 3] == 0
    if im.mode.startswith("I;16") or im.mode == "I":
        a = np.asarray(im).astype(np.int64)
        if a.min() < 0 or a.max() > 65535:
            raise PlanFileError(path, f"{im.mode} pixels outside 0..65535 ({a.min()}..{a.max()}): not a grey image")
        eight = a if im.mode == "I" and a.max() <= 255 else (a + 128) // 257
        return Image.fromarray(eight.astype(np.uint8)), transparent
    if im.mode == "F":
        raise PlanFileError(path, "a floating-point image: save the plan as 8- or 16-bit grey")
    return im.convert("L"), transparent


def _pixels_of_image(path: Path) -> tuple[np.ndarray, np.ndarray]:
    try:
        im = _open_image(path, str(path))
    except ValueError as e:
        raise PlanFileError(path, str(e).removeprefix(f"{path}: ")) from None
    grey, transparent = _grey8(im, path)
    occ, free = _classify_ipa(grey)
    if transparent is not None:  # transparent pixels are unknown, as map_server reads them
        occ, free = occ & ~transparent, free & ~transparent
    return occ, free


def _resample(occ: np.ndarray, free: np.ndarray, f: float) -> tuple[np.ndarray, np.ndarray]:
    """Pixels -> cells of ``f`` pixels a side (``f`` need not be an integer)."""
    H, W = occ.shape
    if f >= 1:
        rows = np.floor(np.arange(math.ceil(H / f)) * f).astype(np.int64)
        cols = np.floor(np.arange(math.ceil(W / f)) * f).astype(np.int64)
        rows, cols = rows[rows < H], cols[cols < W]

        def pool(a: np.ndarray) -> np.ndarray:
            return np.logical_or.reduceat(np.logical_or.reduceat(a, rows, axis=0), cols, axis=1)

        o, fr = pool(occ), pool(free)
        return o, fr & ~o
    rows = np.minimum(np.floor((np.arange(math.floor(H / f)) + 0.5) * f).astype(np.int64), H - 1)
    cols = np.minimum(np.floor((np.arange(math.floor(W / f)) + 0.5) * f).astype(np.int64), W - 1)
    return occ[np.ix_(rows, cols)], free[np.ix_(rows, cols)] & ~occ[np.ix_(rows, cols)]


def load_plan_file(
    path: str | os.PathLike,
    *,
    pixel_size: float | None = None,
    resolution: float = 0.05,
    margin: int | None = 20,
    wall_cells: int = 2,
    outside: str = "occupied",
    name: str | None = None,
    corpus: str = "files",
) -> FloorPlan:
    """Read one plan file (the module docstring) into a :class:`~ogm_ppl.datasets.floorplans.FloorPlan` at
    ``resolution`` metres per cell.

    Args:
        path: a ROS map YAML, a HouseExpo layout or an image (:data:`PLAN_SUFFIXES`).
        pixel_size: metres per pixel of an image (required for one); a ROS map's YAML states its own
            (``resolution``) and a layout is rendered at 0.01 m, so ``pixel_size`` does not apply to them and one
            value serves a folder of all three.
        resolution: metres per cell of the plan returned (the learned priors and guides use 0.05).
        margin, wall_cells, outside: as :func:`~ogm_ppl.datasets.floorplans.load_plan`.
        name: the plan's name (default the file's stem); also its building.
        corpus: the label the plan carries as its corpus.

    Raises:
        PlanFileError: the file is missing, unreadable, malformed, has no free pixel, lacks a scale or would
            give more than :data:`MAX_PLAN_CELLS` cells.
    """
    p = Path(path)
    if p.is_dir():
        raise PlanFileError(p, "a folder, not a plan file: plan_files([folder]) lists the plan files in it")
    if not p.is_file():
        raise PlanFileError(p, "no such plan file")
    suffix = p.suffix.lower()
    if suffix not in PLAN_SUFFIXES:
        raise PlanFileError(p, f"not a plan file: expected one of {', '.join(PLAN_SUFFIXES)}")
    res = _positive(resolution, "resolution", p)
    if suffix in YAML_SUFFIXES:
        occ, free, px = _pixels_of_yaml(p)
    elif suffix in LAYOUT_SUFFIXES:
        verts = _layout_verts(p)
        px = 1.0 / HOUSEEXPO_PX_PER_M
        h, w = layout_size(verts)
        if h * w > MAX_LAYOUT_PIXELS:
            raise PlanFileError(
                p, f"an outline of {w} x {h} pixels of 1 cm, over the limit of {MAX_LAYOUT_PIXELS:,} pixels"
            )
        occ, free = layout_pixels(verts)
    else:
        if pixel_size is None:
            raise PlanFileError(p, "an image has no scale: give its pixel size in metres (pixel_size, --pixel-size)")
        px = _positive(pixel_size, "pixel_size", p)
        occ, free = _pixels_of_image(p)
    f = res / px
    if abs(f - round(f)) <= 1e-5 * f:  # a pixel size written to 6 digits (0.0166667 m: 3 a cell) -> whole blocks
        f = float(round(f))
    cells = math.ceil(occ.shape[0] / f) * math.ceil(occ.shape[1] / f)
    if cells > MAX_PLAN_CELLS:
        raise PlanFileError(
            p,
            f"{occ.shape[1]} x {occ.shape[0]} pixels of {px} m give {cells:,} cells of {res} m, over the limit "
            f"of {MAX_PLAN_CELLS:,}: is the pixel size right?",
        )
    if not free.any():
        raise PlanFileError(p, "no free pixel: not a plan (dark = occupied, light = free)")
    occ, free = _resample(occ, free, f)
    if not free.any():
        raise PlanFileError(
            p, f"no free cell left at {res} m a cell ({f:.3g} pixels of {px} m a cell side): is the pixel size right?"
        )
    occupancy, known = rasterise(occ, free, 1, margin, wall_cells, outside)
    label = p.stem if name is None else str(name)
    return FloorPlan(
        name=label, corpus=corpus, occupancy=occupancy, known=known, resolution=res, building=label, split="test"
    )


def _image_of_yaml(yaml_path: Path) -> Path | None:
    """The image a ROS map's YAML names (resolved), or ``None`` where the YAML cannot be read (the plan reader
    then reports why)."""
    from ogm_ppl.rosmap import RosMapError, read_ros_map_yaml

    try:
        return read_ros_map_yaml(yaml_path)[1].resolve()
    except RosMapError:
        return None


def plan_file_pieces(path: str | os.PathLike) -> list[Path]:
    """The files a plan is read from: the file itself and, for a ROS map's YAML, the image it names (when the
    YAML reads and the image exists)."""
    p = Path(path)
    img = _image_of_yaml(p) if p.suffix.lower() in YAML_SUFFIXES else None
    if img is not None and img.is_relative_to(p.parent.resolve()):
        img = p.parent / img.relative_to(p.parent.resolve())  # as the YAML's path is given: no machine's folder
    return [p] + ([img] if img is not None and img.is_file() else [])


def plan_files(paths: Iterable[str | os.PathLike]) -> list[Path]:
    """The plan files of ``paths`` (files, or folders whose plan files are taken, not recursively), in natural
    order per folder; an image that a YAML among them names is left to that YAML. Raises
    :class:`PlanFileError` for a path that does not exist, a file that is not a plan file, or no plan at all."""
    found: list[Path] = []
    for item in paths:
        p = Path(item)
        if p.is_dir():
            found += sorted(
                (q for q in p.iterdir() if q.is_file() and q.suffix.lower() in PLAN_SUFFIXES),
                key=lambda q: _natural_key(q.name),
            )
        elif p.is_file():
            if p.suffix.lower() not in PLAN_SUFFIXES:
                raise PlanFileError(p, f"not a plan file: expected one of {', '.join(PLAN_SUFFIXES)}")
            found.append(p)
        else:
            raise PlanFileError(p, "no such file or folder")
    seen: set[Path] = set()
    unique = []
    for q in found:  # each file once, the first mention kept
        if q.resolve() not in seen:
            seen.add(q.resolve())
            unique.append(q)
    found = unique
    named = {_image_of_yaml(q) for q in found if q.suffix.lower() in YAML_SUFFIXES}
    out = [q for q in found if q.suffix.lower() in YAML_SUFFIXES or q.resolve() not in named]
    if not out:
        raise PlanFileError(", ".join(str(Path(x)) for x in paths), f"no plan file ({', '.join(PLAN_SUFFIXES)})")
    return out


def plan_names(files: Sequence[Path]) -> list[str]:
    """One distinct name per file: its stem; where stems repeat (``a/ros/map.yaml``, ``b/ros/map.yaml``) the
    path below the files' common folder without the suffix (``a/ros/map``, ``b/ros/map``); where those repeat
    too (``house.png``, ``house.json``), with it. Raises :class:`PlanFileError` for a file given twice."""
    full = [f.resolve() for f in files]
    if len(set(full)) < len(full):
        twice = next(f for f in full if full.count(f) > 1)
        raise PlanFileError(twice, "given twice")
    stems = [f.stem for f in files]
    if len(set(stems)) == len(stems):
        return stems
    root = Path(os.path.commonpath([str(f.parent) for f in full]))
    rel = [f.relative_to(root).with_suffix("").as_posix() for f in full]
    return rel if len(set(rel)) == len(rel) else [f.relative_to(root).as_posix() for f in full]


def render_layout(path: str | os.PathLike) -> np.ndarray:
    """A HouseExpo layout rendered as HouseExpo renders it: ``H x W`` uint8, 255 free (inside the outline), 0
    wall or outside, 1 cm pixels (the ``houseexpo`` corpus's PNGs are such renderings)."""
    p = Path(path)
    occ, _ = layout_pixels(_layout_verts(p))
    return np.where(occ, 0, 255).astype(np.uint8)


# -- is it a corpus plan? ----------------------------------------------------------------------------------------
#: intersection over union of the free pixels at which a plan file is a copy of a corpus plan (variants of one IPA
#: building overlap at 0.92-1.0; two different buildings of the corpora with images of one size at 0.65 at most)
NEAR_COPY = 0.9


@lru_cache(maxsize=4)
def _corpus_digests(root: Path) -> dict[str, str]:
    """SHA-256 of every plan file of the corpora stored as files (HouseExpo, IPA) -> its path."""
    out = {}
    for p in sorted(root.rglob("*")):
        if p.is_file() and p.suffix.lower() in PLAN_SUFFIXES:
            out[hashlib.sha256(p.read_bytes()).hexdigest()] = str(p)
    return out


@lru_cache(maxsize=4)
def _corpus_sizes(root: Path) -> dict[tuple[int, int], list[tuple[str, str]]]:
    """``(rows, cols)`` of every HouseExpo and IPA plan image (from the file headers) -> ``(corpus, name)``."""
    from PIL import Image

    out: dict[tuple[int, int], list[tuple[str, str]]] = {}
    for corpus in ("houseexpo", "ipa"):
        for name in fp.list_plans(corpus, root):
            with Image.open(fp.plan_image_path(corpus, name, root)) as im:
                out.setdefault((im.size[1], im.size[0]), []).append((corpus, name))
    return out


@lru_cache(maxsize=16)
def _corpus_free(root: Path, corpus: str, name: str) -> np.ndarray:
    return plan_pixels(corpus, name, root)[1]


def _plan_free(path: Path) -> np.ndarray:
    """The free pixels of a plan file before resampling (image order)."""
    suffix = path.suffix.lower()
    if suffix in YAML_SUFFIXES:
        return _pixels_of_yaml(path)[1]
    if suffix in LAYOUT_SUFFIXES:
        return layout_pixels(_layout_verts(path))[1]
    return _pixels_of_image(path)[1]


def corpus_copy(path: str | os.PathLike, root=None) -> str | None:
    """What makes a plan file a plan of the floor-plan corpora (so that scoring a prior learned on them on it would
    be leakage), or ``None``: it lies under the corpora's folder; its bytes (for a ROS map, its image's too) are those
    of a HouseExpo or IPA plan file; it is a HouseExpo layout named by the id of a ``houseexpo`` or ``houseexpo-full``
    plan; or its free pixels, in any of the 8 turns and flips, overlap those of a HouseExpo or IPA plan image of the
    same size with an intersection over union of at least :data:`NEAR_COPY` (re-saved, touched up, turned, or a
    variant of the building). A copy at another scale is not caught, and DungeonMaps (synthetic, inside one archive),
    R2V and school plans (vector drawings) are not compared."""
    p = Path(path)
    base = fp.floorplan_root(root).resolve()
    if not base.is_dir():  # no corpora here: nothing to copy
        return None
    for piece in (q.resolve() for q in plan_file_pieces(p)):
        if piece.is_relative_to(base):
            return f"a plan of the floor-plan corpora ({base})"
        same = _corpus_digests(base).get(hashlib.sha256(piece.read_bytes()).hexdigest())
        if same is not None:
            return f"the same bytes as the corpus plan {same}"
    if p.suffix.lower() in LAYOUT_SUFFIXES:
        for corpus in ("houseexpo", "houseexpo-full"):
            try:
                ids = fp.list_plans(corpus, base)
            except fp.CorpusNotFoundError:
                continue
            if p.stem in set(ids):
                return f"the layout of the {corpus} corpus's plan {p.stem}"
    free = _plan_free(p)
    sizes = _corpus_sizes(base)
    for k in range(8):
        a = np.rot90(free, k % 4)
        a = a[:, ::-1] if k >= 4 else a
        for corpus, name in sizes.get(a.shape, []):
            b = _corpus_free(base, corpus, name)
            iou = float((a & b).sum() / max((a | b).sum(), 1))
            if iou >= NEAR_COPY:
                return f"its free space overlaps the {corpus} plan {name}'s at {iou:.1%} (intersection over union)"
    return None
