r"""The full HouseExpo corpus as polygons: ``houseexpo-full`` (33,717 plans in one ``jsonl.gz``).

``houseexpo-full/houseexpo_verts.jsonl.gz`` holds one JSON object per line, sorted by ``id``: ``id`` (the house
id, also the name of a ``houseexpo`` PNG for the 96 houses in both), ``verts`` (the house's outline polygon, ``[x,
y]`` metres, interior walls and door gaps part of it), and fields not read here (``room_num``, ``bbox``,
``room_category``).

Reading is streamed: listing the plans reads each line's ``id`` only (a regular expression on the line's start,
the full JSON where that fails), once per file version; loading plans reads the file once, parsing only the
lines of the plans asked for and yielding them in the order asked. Nothing is rasterised to list a split.

Rasterisation is HouseExpo's own rendering (``pseudoslam/viz/vis_maps.py``, as the ``houseexpo`` PNGs were
made; :func:`layout_pixels`): 1 cm pixels, the vertices truncated to whole centimetres, the polygon filled free,
25 pixels around it, the rest occupied (wall or outside); then the pixel corpora's steps
(:func:`~ogm_ppl.datasets.floorplans._core.rasterise`): downsampled to the resolution (a cell is occupied if
any pixel is), cropped to the free space plus the margin, and the non-free cells more than ``wall_cells`` cells
(default 2, i.e. 0.1 m at 0.05 m) from free space and connected to the edge are outside (unknown). Interior walls
keep the thickness of the polygon's gaps (10-12 cm: 3-4 cells at 0.05 m, as in the ``houseexpo`` corpus); the
exterior wall is ``wall_cells`` cells deep. For the 96 houses in both corpora the grids equal the ``houseexpo``
plans' but for a few pixels on diagonal edges (Pillow's fill against OpenCV's).

Split: by house, with the ``houseexpo`` corpus's hash (``sha256("houseexpo:<id>")``), so a house in both corpora
falls on the same side in both: the subset's test houses are test houses here, and no plan a shipped
``houseexpo`` prior or guide learned from is a test plan here.

Malformed input raises :class:`~ogm_ppl.datasets.floorplans._core.PlanFormatError` naming the file, the line
and the field (``verts[3][1]: 'a' is not a number``); a truncated or corrupt gzip stream names the line it
stopped after.
"""

from __future__ import annotations

import gzip
import json
import math
import re
import zlib
from collections import Counter
from collections.abc import Iterable, Iterator
from functools import lru_cache
from pathlib import Path

import numpy as np

from ogm_ppl.datasets.floorplans._core import PlanFormatError, corpus_path, floorplan_root, natural_key

__all__ = [
    "HOUSEEXPO_PAD",
    "HOUSEEXPO_PX_PER_M",
    "JSONL",
    "MAX_LAYOUT_PIXELS",
    "SPLIT_SALT",
    "jsonl_path",
    "layout_pixels",
    "layout_size",
    "list_ids",
    "parse_verts",
    "records",
]

CORPUS = "houseexpo-full"
JSONL = "houseexpo-full/houseexpo_verts.jsonl.gz"
#: the split hash's salt: the ``houseexpo`` corpus's, so a house in both corpora is on the same side in both
SPLIT_SALT = "houseexpo"
#: HouseExpo's rendering: pixels per metre and exterior pixels around the outline
HOUSEEXPO_PX_PER_M, HOUSEEXPO_PAD = 100, 25
#: Largest HouseExpo rendering (1 cm pixels: a 140 m x 140 m outline)
MAX_LAYOUT_PIXELS = 200_000_000
MAX_VERTS = 100_000
_ID = re.compile(rb'^\s*\{\s*"id"\s*:\s*"([^"\\]+)"')


def jsonl_path(root=None) -> Path:
    """The corpus file (:class:`~ogm_ppl.datasets.floorplans._core.CorpusNotFoundError` when missing)."""
    return corpus_path(floorplan_root(root) / JSONL, CORPUS)


def _lines(path: Path) -> Iterator[tuple[int, bytes]]:
    """``(line number, bytes)`` of the decompressed file, blank lines skipped; a broken stream is a
    :class:`PlanFormatError` naming the line after the last one read."""
    n = 0
    try:
        with gzip.open(path, "rb") as f:
            for n, line in enumerate(f, 1):
                if line.strip():
                    yield n, line
    except (EOFError, OSError, zlib.error) as e:
        raise PlanFormatError(
            path, f"truncated or corrupt gzip stream after line {n} ({type(e).__name__}: {e})", line=n + 1
        ) from None


def _json(line: bytes, path: Path, n: int) -> dict:
    try:
        rec = json.loads(line)
    except (UnicodeDecodeError, json.JSONDecodeError) as e:
        where = f" (column {e.colno})" if isinstance(e, json.JSONDecodeError) else ""
        raise PlanFormatError(path, f"not JSON{where}: {e}", line=n) from None
    if not isinstance(rec, dict):
        raise PlanFormatError(path, f"not a JSON object but {type(rec).__name__}", line=n)
    return rec


def _id(rec: dict, path: Path, n: int) -> str:
    i = rec.get("id")
    if not isinstance(i, str) or not i or "/" in i:
        raise PlanFormatError(path, f"must be a non-empty string without '/', got {i!r}", field="id", line=n)
    return i


def _line_id(line: bytes, path: Path, n: int) -> str:
    m = _ID.match(line)
    return m.group(1).decode("utf-8", "replace") if m else _id(_json(line, path, n), path, n)


@lru_cache(maxsize=4)
def _index(path: str, mtime_ns: int, size: int) -> tuple[tuple[str, ...], dict[str, int]]:
    """Ids in file order and id -> line number (one pass over the file; cached per file version)."""
    ids: list[str] = []
    line_of: dict[str, int] = {}
    for n, line in _lines(Path(path)):
        i = _line_id(line, Path(path), n)
        if i in line_of:
            raise PlanFormatError(path, f"house {i!r} again (first on line {line_of[i]})", field="id", line=n)
        line_of[i] = n
        ids.append(i)
    return tuple(ids), line_of


def _index_of(root=None) -> tuple[Path, tuple[str, ...], dict[str, int]]:
    path = jsonl_path(root)
    st = path.stat()
    ids, line_of = _index(str(path), st.st_mtime_ns, st.st_size)
    return path, ids, line_of


def list_ids(root=None) -> list[str]:
    """Every house id of the corpus, in natural order (the file's ids read once; no polygon parsed)."""
    return sorted(_index_of(root)[1], key=natural_key)


def parse_verts(rec: dict, path: Path | str, n: int | None = None) -> np.ndarray:
    """A record's ``verts`` as an ``N x 2`` float array (metres), validated: at least 3 and at most 100,000
    pairs of finite numbers; else :class:`PlanFormatError` naming ``path``, line ``n`` and the field."""
    if "verts" not in rec:
        raise PlanFormatError(path, "missing (the outline as [[x, y], ...] metres)", field="verts", line=n)
    verts = rec["verts"]
    if not isinstance(verts, list):
        raise PlanFormatError(path, f"must be a list of [x, y], got {type(verts).__name__}", field="verts", line=n)
    if not 3 <= len(verts) <= MAX_VERTS:
        raise PlanFormatError(
            path, f"a polygon needs 3 to {MAX_VERTS:,} vertices, got {len(verts)}", field="verts", line=n
        )
    try:
        a = np.array(verts, dtype=np.float64)
        ok = a.shape == (len(verts), 2) and bool(np.isfinite(a).all())
    except (TypeError, ValueError):
        ok = False
    if ok and all(type(c) in (int, float) for v in verts for c in v):
        return a
    for k, v in enumerate(verts):  # say which vertex and coordinate
        if not isinstance(v, list) or len(v) != 2:
            raise PlanFormatError(path, f"must be a pair [x, y], got {v!r}", field=f"verts[{k}]", line=n)
        for j, c in enumerate(v):
            if type(c) not in (int, float) or not math.isfinite(c):
                raise PlanFormatError(path, f"{c!r} is not a finite number", field=f"verts[{k}][{j}]", line=n)
    raise PlanFormatError(path, "not pairs of finite numbers", field="verts", line=n)  # pragma: no cover


def records(names: Iterable[str], root=None) -> Iterator[tuple[str, np.ndarray]]:
    """``(id, verts)`` of the named houses in the order given (repeats allowed), from one pass over the file:
    lines are parsed only for the names asked for, and held only until their turn. ``KeyError`` for a name not
    in the corpus (before anything is read)."""
    order = list(names)
    path, _, line_of = _index_of(root)
    for i in order:
        if i not in line_of:
            raise KeyError(f"no {CORPUS} plan {i!r} in {path}")
    if not order:
        return
    left = Counter(order)  # how many more times each is yielded
    held: dict[str, np.ndarray] = {}
    k = 0
    for n, line in _lines(path):
        i = _line_id(line, path, n)
        if i not in left:
            continue
        held[i] = parse_verts(_json(line, path, n), path, n)
        while k < len(order) and order[k] in held:
            yield order[k], held[order[k]]
            left[order[k]] -= 1
            if not left[order[k]]:
                del held[order[k]]
            k += 1
        if k == len(order):
            return
    if k < len(order):
        raise PlanFormatError(path, f"house {order[k]!r} no longer in the file (changed while read?)")


# -- HouseExpo's rendering ---------------------------------------------------------------------------------------
def layout_size(verts: np.ndarray) -> tuple[int, int]:
    """``(rows, cols)`` of HouseExpo's 1 cm rendering of ``verts`` (metres)."""
    px = (np.asarray(verts) * HOUSEEXPO_PX_PER_M).astype(np.int64)
    return (
        int(px[:, 1].max() - px[:, 1].min()) + 2 * HOUSEEXPO_PAD,
        int(px[:, 0].max() - px[:, 0].min()) + 2 * HOUSEEXPO_PAD,
    )


def layout_pixels(verts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """HouseExpo's rendering of ``verts`` (``N x 2`` metres): ``(occupied, free)`` ``H x W`` bool at 1 cm, the
    filled outline free, the rest occupied (wall or outside); vertices truncated to whole pixels, 25 pixels
    around."""
    from PIL import Image, ImageDraw

    px = (np.asarray(verts) * HOUSEEXPO_PX_PER_M).astype(np.int64)  # truncated, as the reference renderer does
    px = px - px.min(0) + HOUSEEXPO_PAD
    h, w = layout_size(verts)
    im = Image.new("L", (w, h), 0)
    ImageDraw.Draw(im).polygon([(int(x), int(y)) for x, y in px], fill=255, outline=255)
    free = np.asarray(im) >= 128
    return ~free, free


def checked_pixels(name: str, verts: np.ndarray, root=None) -> tuple[np.ndarray, np.ndarray]:
    """:func:`layout_pixels` of a corpus house, refused (:class:`PlanFormatError`) over :data:`MAX_LAYOUT_PIXELS`."""
    h, w = layout_size(verts)
    if h * w > MAX_LAYOUT_PIXELS:
        raise PlanFormatError(
            jsonl_path(root), f"house {name!r}: {w} x {h} pixels of 1 cm, over {MAX_LAYOUT_PIXELS:,}", field="verts"
        )
    return layout_pixels(verts)
