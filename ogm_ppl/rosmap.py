r"""Maps for robot stacks: ROS ``map_server`` / Nav2 ``map_server`` image + YAML files.

A map is a pair of files (the format of the ROS wiki page *"map_server - ROS Wiki"*, section 1
"Map format", and the Nav2 page *"Map Server / Saver"*): an 8-bit image and a YAML file naming it (a PGM
of another ``maxval``, 16-bit included, is read scaled to 8 bits).
:func:`save_ros_map` writes exactly these YAML fields, in this order and with these types::

    image: map.pgm                  # str: image file name, relative to the YAML file
    mode: trinary                   # str: "trinary" or "scale"
    resolution: 0.05                # float: metres per pixel
    origin: [-1.5, 2.25, 0.0]       # list of 3 floats: (x, y, yaw) of the lower-left pixel's corner
    negate: 0                       # int: 0 or 1
    occupied_thresh: 0.65           # float
    free_thresh: 0.196              # float

Floats are written with Python's shortest round-trip ``repr`` and always contain a ``.`` (``1.0e-05``,
not ``1e-05``), so YAML 1.1 readers (PyYAML) and YAML 1.2 readers (yaml-cpp, used by map_server) both
read them as floats. ``yaw`` is always 0 (an ogm_ppl :class:`~ogm_ppl.grid.Grid` is axis-aligned).

**Pixel -> probability** (what map_server computes, ``x`` the pixel's grey value, the mean of its colour
channels):

.. math::

    p = \begin{cases} (255 - x) / 255 & \text{negate} = 0 \\ x / 255 & \text{negate} = 1 \end{cases}

*trinary*: ``p > occupied_thresh -> 100``, else ``p < free_thresh -> 0``, else ``-1`` (unknown).
*scale*: the same two ends; an image with alpha marks transparent pixels ``-1``; in between the value
is linear in ``p``: Nav2 ``rint(100 r)``, ROS 1 ``int(1 + 98 r)``, with
``r = (p - free_thresh) / (occupied_thresh - free_thresh)``.

**Probability -> pixel** (what we write, before ``negate``; ``negate = 1`` writes ``255 - x``):
*trinary*, as ``map_saver`` writes: ``p > occupied_thresh -> 0`` (black), ``p < free_thresh -> 254``,
else and for unknown cells ``205`` (grey); *scale*: ``x = floor(255 (1 - p) + 1/2)`` for known cells.

Unknown cells, and two traps in the conventions:

* ``thresholds="nav2"`` (free 0.25): Nav2's own map_saver writes unknown as 205 with free_thresh 0.25, and
  205 reads back as ``p = 50/255 = 0.196 < 0.25``, i.e. **free**. By default we therefore write unknown
  cells as the grey in the middle of the unknown band whenever 205 would not read back as unknown
  (140 for ``"nav2"``; 205 for ``"ros1"``). ``unknown_value=205`` forces the map_saver byte (with a
  warning).
* *scale* mode: map_server reads ``-1`` only from an alpha channel, which PGM does not have. A PGM in
  scale mode stores unknown cells as 205 (trinary-compatible, what map_saver writes) and map_server reads
  them as nearly free (0 or 1); a warning says so. Use ``image_format="png"``: we then write grey + alpha
  with unknown cells transparent and, as in trinary, grey inside the unknown band (ROS 1 looks at alpha
  only after the thresholds), which both map_servers read as ``-1``.

The reading side follows the loaders themselves where the wiki is vague: ``map_server/src/image_loader.cpp``
(ROS 1 noetic, ``ros-planning/navigation``) and ``nav2_map_server/src/map_io.cpp`` (``ros-navigation/
navigation2``): strict inequalities, alpha averaged into the grey in trinary mode, ROS 1's ``1 + 98 r``
truncated to an integer and Nav2's ``rint(100 r)`` in scale mode.

Rows: image row 0 is the top of the map (largest ``y``); our cell ``(row, col)`` is image pixel
``(rows - 1 - row, col)`` and OccupancyGrid index ``row * cols + col`` (== our flat cell index).

Next to the two files a *sidecar* ``<stem>.npz`` (``allow_pickle=False``, format version 1) keeps the
float probabilities, the unknown mask, the grid and a SHA-256 of the image (zip-compressed), so that
:func:`load_ros_map` can return the exact probabilities (a stale sidecar is ignored with a warning).
All files are written atomically (:func:`ogm_ppl.io.atomic_write_bytes`); the YAML is written last.

>>> import numpy as np, tempfile, pathlib
>>> g = Grid((2, 3), resolution=0.5, origin=(-1.0, 2.0))
>>> p = np.array([0.9, 0.1, 0.5, 0.1, 0.1, 0.1])
>>> with tempfile.TemporaryDirectory() as d:
...     files = save_ros_map(pathlib.Path(d) / "map.yaml", p, g)
...     m = load_ros_map(files.yaml)
>>> m.occupancy.tolist()
[100, 0, -1, 0, 0, 0]
>>> m.grid == g
True
"""

from __future__ import annotations

import hashlib
import io
import math
import os
import re
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np

from ogm_ppl.grid import Grid
from ogm_ppl.io import atomic_write_bytes

__all__ = [
    "RosMapError",
    "RosMapSettings",
    "RosMapFiles",
    "RosMap",
    "THRESHOLDS",
    "save_ros_map",
    "load_ros_map",
    "read_ros_map_yaml",
    "to_occupancy_grid",
    "from_occupancy_grid",
]

#: ``(occupied_thresh, free_thresh)`` of the two conventions: ROS 1 ``map_saver`` and Nav2 ``map_saver``.
THRESHOLDS: dict[str, tuple[float, float]] = {"ros1": (0.65, 0.196), "nav2": (0.65, 0.25)}
FORMAT_VERSION = 1
_FREE, _OCCUPIED, _UNKNOWN = 254, 0, 205  # map_saver's trinary bytes (before negate)
_MODES = ("trinary", "scale", "raw")
_MAX_PIXELS = 1 << 28
_MAX_YAML_BYTES = 1 << 20
_REQUIRED = ("image", "resolution", "origin", "occupied_thresh", "free_thresh", "negate")


class RosMapError(ValueError):
    """A map file (YAML, image or sidecar) is missing, malformed or inconsistent; names the path."""

    def __init__(self, path: str | os.PathLike, problem: str):
        self.path, self.problem = str(path), problem
        super().__init__(f"{path}: {problem}")


# --------------------------------------------------------------------------- settings / results
@dataclass(frozen=True)
class RosMapSettings:
    """The YAML fields. ``origin`` is ``(x, y, yaw)``; ``extra`` holds keys map_server ignores."""

    image: str
    resolution: float
    origin: tuple[float, float, float]
    negate: bool = False
    occupied_thresh: float = 0.65
    free_thresh: float = 0.196
    mode: str = "trinary"
    extra: dict[str, Any] = field(default_factory=dict)

    def to_yaml(self) -> str:
        """The YAML text :func:`save_ros_map` writes (see the module docstring)."""
        o = ", ".join(_fmt_float(v) for v in self.origin)
        return (
            f"image: {_fmt_str(self.image)}\nmode: {self.mode}\n"
            f"resolution: {_fmt_float(self.resolution)}\norigin: [{o}]\n"
            f"negate: {int(bool(self.negate))}\noccupied_thresh: {_fmt_float(self.occupied_thresh)}\n"
            f"free_thresh: {_fmt_float(self.free_thresh)}\n"
        )


@dataclass(frozen=True)
class RosMapFiles:
    """What :func:`save_ros_map` wrote; ``unknown_value`` is the grey byte used for unknown cells."""

    yaml: Path
    image: Path
    sidecar: Path | None
    settings: RosMapSettings
    unknown_value: int


@dataclass(frozen=True, eq=False)
class RosMap:
    """A map read back by :func:`load_ros_map`.

    Attributes:
        grid: ogm_ppl grid with the file's resolution, origin ``(x, y)`` and shape ``(rows, cols)``
            (the sidecar's 1D grid if the map was saved from one).
        occupancy: ``K`` int8 in ``nav_msgs/OccupancyGrid`` order (row 0 = bottom = origin row), as
            map_server computes it: 0..100, ``-1`` unknown. ``occupancy.reshape(rows, cols)`` is
            grid-shaped.
        probabilities: ``K`` float64 from the sidecar, or None.
        unknown: ``K`` bool never-observed mask from the sidecar, or None.
        settings: the YAML fields.
        pixels: the image as read, ``H x W`` (grey) or ``H x W x C``, row 0 at the top.
    """

    grid: Grid
    occupancy: np.ndarray
    probabilities: np.ndarray | None
    unknown: np.ndarray | None
    settings: RosMapSettings
    pixels: np.ndarray
    yaml_path: Path
    image_path: Path
    sidecar_path: Path | None


# --------------------------------------------------------------------------- OccupancyGrid values
def _thresholds(thresholds: str | Sequence[float]) -> tuple[float, float]:
    if isinstance(thresholds, str):
        if thresholds not in THRESHOLDS:
            raise ValueError(f"thresholds must be one of {sorted(THRESHOLDS)} or (occ, free), got {thresholds!r}")
        return THRESHOLDS[thresholds]
    occ, free = (float(t) for t in thresholds)
    if not (math.isfinite(occ) and math.isfinite(free) and 0.0 <= free < occ <= 1.0):
        raise ValueError(f"thresholds (occupied, free) need 0 <= free < occupied <= 1, got {thresholds!r}")
    return occ, free


def _as_array(x) -> np.ndarray:
    if hasattr(x, "detach"):
        x = x.detach().cpu().numpy()
    return np.asarray(x)


def _probabilities(p, unknown, num_cells: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    p = _as_array(p).astype(np.float64).reshape(-1)
    if num_cells is not None and p.size != num_cells:
        raise ValueError(f"probabilities have {p.size} cells, the grid has {num_cells}")
    nan = np.isnan(p)
    if np.any(~nan & ~((p >= 0) & (p <= 1))):
        raise ValueError("probabilities must lie in [0, 1] (NaN marks unknown cells)")
    unk = nan.copy()
    if unknown is not None:
        u = _as_array(unknown)
        if u.dtype != np.bool_:
            raise ValueError(f"unknown must be a bool mask, got dtype {u.dtype}")
        if u.size != p.size:
            raise ValueError(f"unknown has {u.size} entries, probabilities {p.size}")
        unk |= u.reshape(-1)
    return p, unk


def to_occupancy_grid(
    probabilities,
    unknown=None,
    thresholds: str | Sequence[float] = "ros1",
    *,
    mode: Literal["trinary", "scale", "linear"] = "trinary",
) -> np.ndarray:
    r"""Probabilities -> ``nav_msgs/OccupancyGrid.data``: ``K`` int8, 0..100, ``-1`` unknown.

    Row-major from the origin cell (row 0 = lowest ``y``), which is our flat cell index: a grid-shaped
    input is flattened, not flipped. ``unknown`` (``K`` or grid-shaped bool) and NaN cells give ``-1``.

    * ``"trinary"``: ``p > occ -> 100``, ``p < free -> 0``, else ``-1``; equals what map_server reads
      back from a trinary :func:`save_ros_map` export with the same thresholds.
    * ``"scale"``: the ends as above, in between ``rint(100 (p - free) / (occ - free))`` (Nav2's scale
      formula applied to ``p`` itself, without the 8-bit image in between).
    * ``"linear"``: ``floor(100 p + 1/2)``, thresholds unused (the convention of SLAM packages that
      publish continuous maps).

    ``thresholds``: ``"ros1"`` (0.65, 0.196), ``"nav2"`` (0.65, 0.25) or ``(occupied, free)``.

    >>> to_occupancy_grid([0.9, 0.1, 0.5, 0.3], thresholds="nav2").tolist()
    [100, 0, -1, -1]
    """
    p, unk = _probabilities(probabilities, unknown)
    occ, free = _thresholds(thresholds)
    q = np.where(np.isnan(p), 0.5, p)
    if mode == "trinary":
        out = np.where(q > occ, 100, np.where(q < free, 0, -1))
    elif mode == "scale":
        mid = np.rint((q - free) / (occ - free) * 100.0)
        out = np.where(q > occ, 100, np.where(q < free, 0, mid))
    elif mode == "linear":
        out = np.floor(100.0 * q + 0.5)
    else:
        raise ValueError(f"mode must be 'trinary', 'scale' or 'linear', got {mode!r}")
    out = np.asarray(out, dtype=np.int64)
    out[unk] = -1
    return out.astype(np.int8)


def from_occupancy_grid(data, *, unknown_probability: float = 0.5) -> tuple[np.ndarray, np.ndarray]:
    """``OccupancyGrid.data`` -> ``(probabilities, unknown)``, both shaped like ``data``.

    ``p = value / 100`` for 0..100; any other value (``-1``) is unknown and gets ``unknown_probability``.

    >>> p, u = from_occupancy_grid(np.array([0, 100, -1, 50], dtype=np.int8))
    >>> p.tolist(), u.tolist()
    ([0.0, 1.0, 0.5, 0.5], [False, False, True, False])
    """
    d = _as_array(data)
    if not np.issubdtype(d.dtype, np.integer):
        raise ValueError(f"OccupancyGrid data must be integers, got dtype {d.dtype}")
    d = d.astype(np.int64)
    unknown = (d < 0) | (d > 100)
    p = np.where(unknown, float(unknown_probability), d / 100.0)
    return p, unknown


# --------------------------------------------------------------------------- pixels
def _occ_of_shade(avg: np.ndarray, negate: bool, flavor: str) -> np.ndarray:
    if flavor == "ros1":  # color_avg = 255 - color_avg if negate; occ = (255 - color_avg) / 255.0
        a = 255.0 - avg if negate else avg
        return (255.0 - a) / 255.0
    shade = avg / 255.0  # Nav2: occ = negate ? shade : 1.0 - shade
    return shade if negate else 1.0 - shade


def _interpret(pixels: np.ndarray, s: RosMapSettings, flavor: str) -> np.ndarray:
    """map_server's reading of an image (``H x W`` or ``H x W x C``) -> OccupancyGrid ``K`` int8."""
    px = pixels.astype(np.float64)
    if px.ndim == 2:
        px = px[..., None]
    nc = px.shape[-1]
    has_alpha = nc in (2, 4)
    colour = px[..., : nc - 1] if has_alpha else px
    if colour.shape[-1] == 1:  # grey: map_server sees R = G = B
        colour = np.repeat(colour, 3, axis=-1)
    alpha = px[..., -1] if has_alpha else None
    chans = np.concatenate([colour, alpha[..., None]], -1) if (alpha is not None and s.mode == "trinary") else colour
    avg = chans.mean(axis=-1)
    occ_t, free_t = s.occupied_thresh, s.free_thresh
    if s.mode == "raw":
        if flavor == "ros1":  # value = color_avg (unsigned char), stored in int8 data
            v = np.trunc(255.0 - avg if s.negate else avg).astype(np.uint8).view(np.int8)
        else:
            v = np.floor(avg + 0.5)
            v = np.where((v >= 0) & (v <= 100), v, -1).astype(np.int8)
        return v[::-1].reshape(-1)
    occ = _occ_of_shade(avg, s.negate, flavor)
    out = np.full(avg.shape, -1, dtype=np.int64)
    is_occ, is_free = occ > occ_t, occ < free_t
    out[is_occ] = 100
    out[~is_occ & is_free] = 0
    if s.mode == "scale":
        mid = ~is_occ & ~is_free
        r = (occ - free_t) / (occ_t - free_t) if occ_t > free_t else np.zeros_like(occ)
        if flavor == "ros1":
            out[mid] = np.trunc(1.0 + 98.0 * r[mid])
            if alpha is not None:
                out[mid & (alpha < 1.0)] = -1
        else:
            out[mid] = np.rint(r[mid] * 100.0)
            if alpha is not None:
                out[alpha < 255.0] = -1
    return out[::-1].reshape(-1).astype(np.int8)


def _reads_unknown(value: int, occ_t: float, free_t: float, negate: bool) -> bool:
    x = np.array([float(value)])
    return all(not (o > occ_t) and not (o < free_t) for o in (_occ_of_shade(x, negate, f)[0] for f in ("ros1", "nav2")))


def _default_unknown_value(occ_t: float, free_t: float) -> int:
    if _reads_unknown(_UNKNOWN, occ_t, free_t, False):
        return _UNKNOWN
    mid = math.floor(255.0 * (1.0 - (occ_t + free_t) / 2.0) + 0.5)
    for v in sorted(range(256), key=lambda v: abs(v - mid)):
        if _reads_unknown(v, occ_t, free_t, False) and _reads_unknown(255 - v, occ_t, free_t, True):
            return v
    raise ValueError(f"no 8-bit grey reads back as unknown between free {free_t} and occupied {occ_t}")


# --------------------------------------------------------------------------- writing
def _fmt_float(x: float) -> str:
    s = repr(float(x))
    if "e" in s and "." not in s.split("e")[0]:
        mant, exp = s.split("e")
        s = f"{mant}.0e{exp}"
    return s


def _fmt_str(s: str) -> str:
    if re.fullmatch(r"[A-Za-z0-9_][A-Za-z0-9_.\-/]*", s) and _FLOAT_RE.fullmatch(s) is None:
        return s
    return '"' + s.replace("\\", "\\\\").replace('"', '\\"') + '"'


def _paths(path: str | os.PathLike, image_format: str) -> tuple[Path, Path, Path]:
    p = Path(path)
    stem = p.with_suffix("") if p.suffix.lower() in (".yaml", ".yml") else p
    yaml_path = p if p.suffix.lower() in (".yaml", ".yml") else Path(str(p) + ".yaml")
    return yaml_path, Path(str(stem) + "." + image_format), Path(str(stem) + ".npz")


def save_ros_map(
    path: str | os.PathLike,
    probabilities,
    grid: Grid | None = None,
    *,
    unknown=None,
    mode: Literal["trinary", "scale"] = "trinary",
    thresholds: str | Sequence[float] = "ros1",
    negate: bool = False,
    image_format: Literal["pgm", "png"] = "pgm",
    sidecar: bool = True,
    unknown_value: int | None = None,
) -> RosMapFiles:
    r"""Write a map_server map: ``<stem>.pgm`` (or ``.png``), ``<stem>.yaml`` and ``<stem>.npz``.

    Args:
        path: the YAML path (``.yaml``/``.yml``) or the stem; the directory is created.
        probabilities: ``K`` or grid-shaped ``p(m_k = 1 | z)`` (numpy or torch); NaN = unknown. A
            :class:`~ogm_ppl.inference.log_odds.maps.LogOddsMap` is accepted too (its grid, and
            ``~observed`` as the unknown mask).
        grid: the grid (its ``origin`` becomes the YAML origin; a 1D grid is one image row).
        unknown: ``K`` or grid-shaped bool mask of never-observed cells.
        mode: ``"trinary"`` (0 / 254 / grey) or ``"scale"`` (``x = floor(255 (1 - p) + 1/2)``).
        thresholds: ``"ros1"`` -> occupied 0.65, free 0.196 (ROS 1 map_saver); ``"nav2"`` -> 0.65, 0.25
            (Nav2 map_saver defaults); or ``(occupied, free)``.
        negate: write ``negate: 1`` and ``255 - x`` for every pixel (the map reads back the same).
        image_format: ``"pgm"`` (binary P5, 8 bit) or ``"png"`` (needs Pillow; grey + alpha in scale
            mode so that unknown cells are transparent).
        sidecar: also write ``<stem>.npz`` with the float probabilities, unknown mask and grid.
        unknown_value: grey byte (before negate) for unknown cells in trinary mode; default 205 when
            that reads back as unknown under ``thresholds``, else the middle of the unknown band.

    Returns:
        :class:`RosMapFiles` with the three paths and the settings written.
    """
    if grid is None and hasattr(probabilities, "grid") and hasattr(probabilities, "observed"):
        grid = probabilities.grid
        if unknown is None:
            unknown = ~_as_array(probabilities.observed).astype(bool)
        probabilities = probabilities.probabilities
    if not isinstance(grid, Grid):
        raise TypeError(f"grid must be an ogm_ppl Grid, got {type(grid).__name__}")
    if mode not in ("trinary", "scale"):
        raise ValueError(f"mode must be 'trinary' or 'scale', got {mode!r}")
    if image_format not in ("pgm", "png"):
        raise ValueError(f"image_format must be 'pgm' or 'png', got {image_format!r}")
    occ_t, free_t = _thresholds(thresholds)
    p, unk = _probabilities(probabilities, unknown, grid.num_cells)
    if mode == "trinary":
        if not (free_t > 1 / 255 and occ_t < 1.0):
            raise ValueError("trinary maps need free_thresh > 1/255 and occupied_thresh < 1")
        if unknown_value is None:
            unknown_value = _default_unknown_value(occ_t, free_t)
        elif not _reads_unknown(int(unknown_value), occ_t, free_t, False):
            warnings.warn(
                f"unknown_value={unknown_value} reads back as known (not -1) under thresholds "
                f"occupied={occ_t}, free={free_t}",
                UserWarning,
                stacklevel=2,
            )
        x = np.where(p > occ_t, _OCCUPIED, np.where(p < free_t, _FREE, int(unknown_value)))
    else:
        # with alpha, the grey must lie in the unknown band too (ROS 1 checks alpha last)
        if unknown_value is None:
            png = image_format == "png"
            unknown_value = _default_unknown_value(occ_t, free_t) if png else _UNKNOWN
        x = np.floor(255.0 * (1.0 - np.where(np.isnan(p), 0.5, p)) + 0.5)
        if image_format == "pgm" and unk.any():
            warnings.warn(
                "scale mode in a PGM cannot mark unknown cells (no alpha channel): they are "
                "written as 205 and map_server reads them as (nearly) free; use "
                "image_format='png'",
                UserWarning,
                stacklevel=2,
            )
    if not 0 <= int(unknown_value) <= 255:
        raise ValueError(f"unknown_value must be a byte, got {unknown_value}")
    x = np.where(unk, int(unknown_value), x).astype(np.int64)
    if negate:
        x = 255 - x
    img = x.astype(np.uint8).reshape(grid.rows, grid.cols)[::-1]

    yaml_path, image_path, npz_path = _paths(path, image_format)
    if image_format == "pgm":
        header = f"P5\n# CREATOR: ogm_ppl.rosmap {grid.resolution:.3f} m/pix\n{grid.cols} {grid.rows}\n255\n"
        data = header.encode("ascii") + np.ascontiguousarray(img).tobytes()
    else:
        from PIL import Image

        buf = io.BytesIO()
        if mode == "scale":
            alpha = np.where(unk, 0, 255).astype(np.uint8).reshape(grid.rows, grid.cols)[::-1]
            Image.fromarray(np.ascontiguousarray(np.stack([img, alpha], -1))).save(buf, "PNG")  # LA
        else:
            Image.fromarray(np.ascontiguousarray(img)).save(buf, "PNG")  # L
        data = buf.getvalue()
    settings = RosMapSettings(
        image=image_path.name,
        resolution=grid.resolution,
        origin=(grid.origin[0], grid.origin[1], 0.0),
        negate=bool(negate),
        occupied_thresh=occ_t,
        free_thresh=free_t,
        mode=mode,
    )
    atomic_write_bytes(image_path, data)
    if sidecar:
        buf = io.BytesIO()
        np.savez_compressed(  # a map's probabilities repeat (the prior's value where unobserved): zip shrinks them
            buf,
            format_version=np.int64(FORMAT_VERSION),
            probabilities=p,
            unknown=unk,
            shape=np.asarray(grid.shape, dtype=np.int64),
            resolution=np.float64(grid.resolution),
            origin=np.asarray(grid.origin, dtype=np.float64),
            image_sha256=np.str_(hashlib.sha256(data).hexdigest()),
        )
        atomic_write_bytes(npz_path, buf.getvalue())
    atomic_write_bytes(yaml_path, settings.to_yaml().encode("utf-8"))
    return RosMapFiles(yaml_path, image_path, npz_path if sidecar else None, settings, int(unknown_value))


# --------------------------------------------------------------------------- YAML subset
_FLOAT_RE = re.compile(r"[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?")
_INT_RE = re.compile(r"[-+]?\d+")
_KEY_RE = re.compile(r"""(?:"((?:[^"\\]|\\.)*)"|'((?:[^']|'')*)'|([A-Za-z_][\w\-.]*))[ \t]*:(?:[ \t]+(.*))?""")
_TRUE, _FALSE = {"true", "yes", "on", "y"}, {"false", "no", "off", "n"}
_NONFINITE = {".inf", "+.inf", "-.inf", ".nan", "inf", "+inf", "-inf", "nan", "infinity"}


def _strip_comment(line: str) -> str:
    quote = None
    for i, ch in enumerate(line):
        if quote:
            if ch == quote:
                quote = None
        elif ch in "\"'" and (i == 0 or line[i - 1] in " \t[,:"):
            quote = ch
        elif ch == "#" and (i == 0 or line[i - 1] in " \t"):
            return line[:i]
    return line


def _scalar(text: str, where: str) -> str:
    t = text.strip()
    if t[:1] == '"':
        if len(t) < 2 or t[-1] != '"':
            raise ValueError(f"{where}: unterminated double-quoted string")
        body = t[1:-1]
        return re.sub(r"\\(.)", lambda m: {"n": "\n", "t": "\t"}.get(m.group(1), m.group(1)), body)
    if t[:1] == "'":
        if len(t) < 2 or t[-1] != "'":
            raise ValueError(f"{where}: unterminated single-quoted string")
        return t[1:-1].replace("''", "'")
    if t[:1] in ("{", "|", ">", "&", "*", "!", "@", "`"):
        raise ValueError(f"{where}: unsupported YAML construct {t[:1]!r}")
    return t


def _flow_seq(text: str, where: str) -> list[str]:
    t = text.strip()
    if not t.endswith("]"):
        raise ValueError(f"{where}: unterminated flow sequence")
    body = t[1:-1]
    if "[" in body or "{" in body:
        raise ValueError(f"{where}: nested collections are not supported")
    items, cur, quote = [], "", None
    for ch in body:
        if quote:
            quote = None if ch == quote else quote
        elif ch in "\"'":
            quote = ch
        elif ch == ",":
            items.append(cur)
            cur = ""
            continue
        cur += ch
    if cur.strip() or items:
        items.append(cur)
    if items and not items[-1].strip():  # a trailing comma is allowed in YAML flow sequences
        items.pop()
    if any(not i.strip() for i in items):
        raise ValueError(f"{where}: empty item in flow sequence")
    return [_scalar(i, where) for i in items]


def _parse_yaml(text: str) -> dict[str, Any]:
    """The flat YAML that map files use: ``key: scalar`` and one list, flow or block; first document."""
    out: dict[str, Any] = {}
    pending: str | None = None
    for n, raw in enumerate(text.splitlines(), 1):
        where = f"line {n}"
        line = _strip_comment(raw).rstrip()
        if not line.strip():
            continue
        if line.strip() in ("---", "..."):
            if out:
                break
            continue
        if line.startswith("%"):
            continue  # directive
        stripped = line.lstrip(" ")
        if stripped.startswith("\t") or (line[:1] == "\t"):
            raise ValueError(f"{where}: tabs cannot indent YAML")
        if stripped[:1] == "-" and (stripped == "-" or stripped[1:2] in (" ", "\t")):
            if pending is None:
                raise ValueError(f"{where}: list item outside a list")
            out[pending].append(_scalar(stripped[1:], where))
            continue
        if stripped is not line:
            raise ValueError(f"{where}: unexpected indentation (nested mappings are not supported)")
        if pending is not None and not out[pending]:
            out[pending] = None
        pending = None
        m = _KEY_RE.fullmatch(line)
        if m is None:
            raise ValueError(f"{where}: expected 'key: value', got {raw.strip()!r}")
        key = m.group(3) or (m.group(1) if m.group(1) is not None else (m.group(2) or "").replace("''", "'"))
        if key in out:
            raise ValueError(f"{where}: duplicate key {key!r}")
        value = (m.group(4) or "").strip()
        if not value:
            out[key], pending = [], key
        elif value.startswith("["):
            out[key] = _flow_seq(value, where)
        else:
            out[key] = _scalar(value, where)
    if pending is not None and not out[pending]:
        out[pending] = None
    return out


def _get_float(doc: dict, key: str, path: Path) -> float:
    v = doc[key]
    if not isinstance(v, str):
        raise RosMapError(path, f"{key!r} must be a number, got {type(v).__name__}")
    return _to_float(v, key, path)


def _to_float(v: str, key: str, path: Path) -> float:
    if v.lower() in _NONFINITE:
        raise RosMapError(path, f"{key!r} must be finite, got {v!r}")
    if _FLOAT_RE.fullmatch(v) is None:
        raise RosMapError(path, f"{key!r} must be a number, got {v!r}")
    x = float(v)
    if not math.isfinite(x):
        raise RosMapError(path, f"{key!r} must be finite, got {v!r}")
    return x


def _settings(doc: dict, path: Path) -> RosMapSettings:
    missing = [k for k in _REQUIRED if k not in doc]
    if missing:
        raise RosMapError(path, f"missing required key(s) {', '.join(missing)}")
    image = doc["image"]
    if not isinstance(image, str) or not image:
        raise RosMapError(path, "'image' must be a non-empty file name")
    res = _get_float(doc, "resolution", path)
    if res <= 0:
        raise RosMapError(path, f"'resolution' must be positive, got {res}")
    origin = doc["origin"]
    if not isinstance(origin, list) or len(origin) != 3:
        raise RosMapError(path, "'origin' must be a list of 3 numbers [x, y, yaw]")
    if not all(isinstance(v, str) for v in origin):
        raise RosMapError(path, "'origin' must be a list of 3 numbers [x, y, yaw]")
    ox, oy, oyaw = (_to_float(v, "origin", path) for v in origin)
    origin_t = (ox, oy, oyaw)
    occ, free = _get_float(doc, "occupied_thresh", path), _get_float(doc, "free_thresh", path)
    if not 0.0 <= free < occ <= 1.0:
        raise RosMapError(path, f"thresholds need 0 <= free_thresh < occupied_thresh <= 1, got {free}, {occ}")
    neg = doc["negate"]
    if isinstance(neg, str) and _INT_RE.fullmatch(neg):
        negate = int(neg) != 0
    elif isinstance(neg, str) and neg.lower() in _TRUE | _FALSE:
        negate = neg.lower() in _TRUE
    else:
        raise RosMapError(path, f"'negate' must be 0 or 1, got {neg!r}")
    mode = doc.get("mode", "trinary")
    if mode is None:
        mode = "trinary"
    if mode not in _MODES:
        raise RosMapError(path, f"'mode' must be one of {', '.join(_MODES)}, got {mode!r}")
    extra = {k: v for k, v in doc.items() if k not in (*_REQUIRED, "mode")}
    return RosMapSettings(image, res, origin_t, negate, occ, free, mode, extra)


# --------------------------------------------------------------------------- image reading
def _extra_data(n: int, what: str, w: int, h: int) -> str:
    return (
        f"PGM has {n} pixel {what} after the {w} x {h} its header states: the header's size is wrong, or the "
        "file holds several images (a map is one)"
    )


def _read_pnm(data: bytes, path: Path) -> np.ndarray:
    magic = data[:2]
    pos, n = 2, len(data)
    tokens: list[int] = []
    if n < 3 or not (data[2:3].isspace() or data[2] == ord("#")):
        raise RosMapError(path, "PGM bad header (magic number must be followed by whitespace)")
    while len(tokens) < 3:
        while pos < n and (data[pos : pos + 1].isspace() or data[pos] == ord("#")):
            if data[pos] == ord("#"):
                while pos < n and data[pos] not in (10, 13):
                    pos += 1
            else:
                pos += 1
        start = pos
        while pos < n and 48 <= data[pos] <= 57:
            pos += 1
        if pos == start:
            what = "truncated header" if pos >= n else f"bad header byte {data[pos : pos + 1]!r}"
            raise RosMapError(path, f"PGM {what} (expected width, height, maxval)")
        tokens.append(int(data[start:pos]))
        last = len(tokens) == 3
        if pos < n and not data[pos : pos + 1].isspace() and (last or data[pos] != ord("#")):
            raise RosMapError(path, f"PGM bad header byte {data[pos : pos + 1]!r}")
    w, h, maxval = tokens
    if w < 1 or h < 1 or w * h > _MAX_PIXELS:
        raise RosMapError(path, f"PGM size {w} x {h} is not a usable image size")
    if not 1 <= maxval <= 65535:
        raise RosMapError(path, f"PGM maxval {maxval} unsupported (need 1..65535)")
    px: np.ndarray
    if magic == b"P5":
        if pos >= n:
            raise RosMapError(path, "PGM truncated: no pixel data")
        size = w * h * (1 if maxval <= 255 else 2)  # 16-bit samples: two bytes each, most significant first
        raw = data[pos + 1 : pos + 1 + size]
        if len(raw) < size:
            raise RosMapError(path, f"PGM truncated: {len(raw)} of {size} pixel bytes")
        extra = data[pos + 1 + size :]
        if extra.strip():
            raise RosMapError(path, _extra_data(len(extra), "bytes", w, h))
        px = np.frombuffer(raw, dtype=np.uint8 if maxval <= 255 else ">u2").reshape(h, w).astype(np.int64)
    else:  # P2, ASCII
        body = data[pos:].split()
        if len(body) < w * h:
            raise RosMapError(path, f"PGM truncated: {len(body)} of {w * h} pixel values")
        if len(body) > w * h:
            raise RosMapError(path, _extra_data(len(body) - w * h, "values", w, h))
        try:
            px = np.array([int(t) for t in body[: w * h]], dtype=np.int64).reshape(h, w)
        except ValueError:
            raise RosMapError(path, "PGM pixel data are not integers") from None
    if px.max(initial=0) > maxval or px.min(initial=0) < 0:
        raise RosMapError(path, f"PGM pixel value above maxval {maxval}")
    if maxval != 255:
        px = (px.astype(np.int64) * 255 + maxval // 2) // maxval
    return px.astype(np.uint8)


def _read_image(path: Path) -> tuple[np.ndarray, bytes]:
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        raise RosMapError(path, "image file not found") from None
    except OSError as e:
        raise RosMapError(path, f"cannot read image file ({e.strerror or e})") from None
    if data[:2] in (b"P5", b"P2"):
        return _read_pnm(data, path), data
    if data[:1] == b"P" and data[1:2] in b"1346":
        raise RosMapError(path, f"PNM type {data[:2].decode()} unsupported (use P5 / P2 greyscale)")
    try:
        from PIL import Image

        im: Image.Image  # convert() below returns a plain Image
        with Image.open(io.BytesIO(data)) as im:
            if im.size[0] * im.size[1] > _MAX_PIXELS:
                raise RosMapError(path, f"image size {im.size} too large")
            im.load()
            if im.mode == "P":
                im = im.convert("RGBA" if "transparency" in im.info else "RGB")
            elif im.mode == "1":
                im = im.convert("L")
            if im.mode not in ("L", "LA", "RGB", "RGBA"):
                raise RosMapError(path, f"image mode {im.mode} unsupported (8-bit grey or colour)")
            px = np.asarray(im, dtype=np.uint8).copy()
    except RosMapError:
        raise
    except Exception as e:  # Pillow raises many types on corrupt files
        why = "unrecognised format" if type(e).__name__ == "UnidentifiedImageError" else f"{type(e).__name__}: {e}"
        raise RosMapError(path, f"not a readable image ({why})") from None
    return px, data


def _read_sidecar(path: Path, image_bytes: bytes, settings: RosMapSettings, hw: tuple[int, int]):
    try:
        with np.load(path, allow_pickle=False) as z:
            d = {k: z[k] for k in z.files}
    except Exception as e:
        raise RosMapError(path, f"sidecar is not a readable npz ({type(e).__name__}: {e})") from None
    need = (
        "format_version",
        "probabilities",
        "unknown",
        "shape",
        "resolution",
        "origin",
        "image_sha256",
    )
    missing = [k for k in need if k not in d]
    if missing:
        raise RosMapError(path, f"sidecar misses {', '.join(missing)}")
    ver = d["format_version"]
    if ver.shape != () or ver.dtype.kind not in "iu" or int(ver) != FORMAT_VERSION:
        raise RosMapError(path, f"sidecar format version {d['format_version']!r} unsupported")
    p, unk, shape = d["probabilities"], d["unknown"], d["shape"]
    if p.dtype.kind != "f" or unk.dtype != np.bool_ or shape.dtype.kind != "i" or shape.ndim != 1:
        raise RosMapError(path, "sidecar arrays have wrong dtypes")
    if str(d["image_sha256"]) != hashlib.sha256(image_bytes).hexdigest():
        warnings.warn(f"{path}: sidecar is stale (written for another image); ignored", UserWarning, stacklevel=3)
        return None
    K = hw[0] * hw[1]
    if p.shape != (K,) or unk.shape != (K,) or int(np.prod(shape)) != K or len(shape) not in (1, 2):
        raise RosMapError(path, "sidecar shape does not match the image")
    if not np.all(np.isnan(p) | ((p >= 0) & (p <= 1))) or np.any(np.isnan(p) & ~unk):
        raise RosMapError(path, "sidecar probabilities outside [0, 1]")
    if (len(shape) == 2 and tuple(shape) != hw) or (len(shape) == 1 and hw[0] != 1):
        raise RosMapError(path, "sidecar grid shape does not match the image")
    same = (
        float(d["resolution"]) == settings.resolution
        and tuple(np.asarray(d["origin"], float).tolist()) == settings.origin[:2]
    )
    if not same:
        warnings.warn(
            f"{path}: sidecar grid differs from the YAML resolution/origin; ignored", UserWarning, stacklevel=3
        )
        return None
    return p.astype(np.float64), unk, tuple(int(s) for s in shape)


def read_ros_map_yaml(yaml_path: str | os.PathLike) -> tuple[RosMapSettings, Path]:
    """The YAML of a map_server map, validated as :func:`load_ros_map` reads it: its settings and the path of the
    image it names (a relative ``image`` resolved against the YAML's directory; the image is not read).

    Raises:
        RosMapError: a missing, unreadable or malformed YAML, naming the path and the problem.
    """
    path = Path(yaml_path)
    try:
        raw = path.read_bytes()
    except FileNotFoundError:
        raise RosMapError(path, "YAML file not found") from None
    except OSError as e:
        raise RosMapError(path, f"cannot read YAML file ({e.strerror or e})") from None
    if len(raw) > _MAX_YAML_BYTES:
        raise RosMapError(path, "YAML file too large for map metadata")
    try:
        doc = _parse_yaml(raw.decode("utf-8-sig"))
    except UnicodeDecodeError:
        raise RosMapError(path, "YAML is not UTF-8 text") from None
    except ValueError as e:
        raise RosMapError(path, f"malformed YAML: {e}") from None
    s = _settings(doc, path)
    image_path = Path(os.path.expanduser(s.image))
    return s, image_path if image_path.is_absolute() else path.parent / image_path


def load_ros_map(yaml_path: str | os.PathLike, *, flavor: Literal["nav2", "ros1"] = "nav2") -> RosMap:
    """Read a map_server map (YAML + image) and, if present, its ``<stem>.npz`` sidecar.

    ``occupancy`` is what map_server publishes (see the module docstring for the formulas); ``flavor``
    picks Nav2's or ROS 1's reading where they differ (scale mode's middle values, alpha, raw mode).
    The YAML accepted is what map_server accepts in practice: comments, quoted strings, flow or block
    ``origin``, ``negate`` as an int or a bool, ``mode`` optional (trinary), extra keys ignored;
    images: binary/ASCII PGM (own reader, strictly validated) and whatever Pillow opens (PNG, BMP ...).
    A relative ``image`` is resolved against the YAML's directory.

    Raises:
        RosMapError: a missing or malformed file, naming the path and the problem.
    """
    if flavor not in ("nav2", "ros1"):
        raise ValueError(f"flavor must be 'nav2' or 'ros1', got {flavor!r}")
    path = Path(yaml_path)
    s, image_path = read_ros_map_yaml(path)
    pixels, image_bytes = _read_image(image_path)
    h, w = pixels.shape[:2]
    if s.origin[2] != 0.0:
        warnings.warn(
            f"{path}: origin yaw {s.origin[2]} ignored (ogm_ppl grids are axis-aligned)", UserWarning, stacklevel=2
        )
    occupancy = _interpret(pixels, s, flavor)
    stem = path.with_suffix("") if path.suffix.lower() in (".yaml", ".yml") else path
    npz = Path(str(stem) + ".npz")
    side = _read_sidecar(npz, image_bytes, s, (h, w)) if npz.exists() else None
    shape = side[2] if side is not None else (h, w)
    grid = Grid(shape, resolution=s.resolution, origin=s.origin[:2])
    return RosMap(
        grid=grid,
        occupancy=occupancy,
        probabilities=None if side is None else side[0],
        unknown=None if side is None else side[1],
        settings=s,
        pixels=pixels,
        yaml_path=path,
        image_path=image_path,
        sidecar_path=npz if side is not None else None,
    )
