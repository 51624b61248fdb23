"""A map_server map saved (:func:`save_ros_map`) and loaded (:func:`load_ros_map`): the image, the YAML and
the sidecar together."""

from __future__ import annotations

import os
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np

from ogm_ppl.grid import Grid
from ogm_ppl.io import atomic_write_bytes
from ogm_ppl.rosmap._image import _encode_image, _read_image
from ogm_ppl.rosmap._occupancy import (
    _FREE,
    _OCCUPIED,
    _UNKNOWN,
    _as_array,
    _default_unknown_value,
    _interpret,
    _probabilities,
    _reads_unknown,
    _thresholds,
)
from ogm_ppl.rosmap._sidecar import _read_sidecar, _sidecar_bytes
from ogm_ppl.rosmap._yaml import RosMapSettings, read_ros_map_yaml


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
    alpha = (
        np.where(unk, 0, 255).astype(np.uint8).reshape(grid.rows, grid.cols)[::-1]
        if mode == "scale" and image_format == "png"
        else None
    )
    data = _encode_image(img, image_format, grid.resolution, alpha)
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
        atomic_write_bytes(npz_path, _sidecar_bytes(p, unk, grid, data))
    atomic_write_bytes(yaml_path, settings.to_yaml().encode("utf-8"))
    return RosMapFiles(yaml_path, image_path, npz_path if sidecar else None, settings, int(unknown_value))


def load_ros_map(yaml_path: str | os.PathLike, *, flavor: Literal["nav2", "ros1"] = "nav2") -> RosMap:
    """Read a map_server map (YAML + image) and, if present, its ``<stem>.npz`` sidecar.

    ``occupancy`` is what map_server publishes (the formulas of :mod:`ogm_ppl.rosmap`); ``flavor``
    picks Nav2's or ROS 1's reading where they differ (scale mode's middle values, alpha, raw mode).
    The YAML (read with ruamel.yaml's safe loader, constructing nothing; tags other than YAML's own types
    are refused) is what map_server accepts in practice: comments, quoted strings, flow or block
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
