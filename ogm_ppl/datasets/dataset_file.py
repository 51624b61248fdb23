"""One file format for a dataset: scans, optionally a grid and a ground-truth map, settings, provenance.

An ``.npz`` archive written with ``allow_pickle=False`` semantics (plain arrays only; read back with
``allow_pickle=False``, so a file from a colleague cannot run code) holding:

==================  ==============================  =============================================
key                 dtype / shape                   meaning
==================  ==============================  =============================================
``format``          str                             ``"ogm_ppl.dataset"``
``format_version``  int64 scalar                    1
``poses``           float64 ``S x 3``               scan poses ``(x, y, yaw)``
``angles``          float64 ``S x B``               beam angles relative to the yaw
``ranges``          float64 ``S x B``               ranges (0 where not valid)
``valid``           bool ``S x B``                  beams that are readings
``max_range``       float64 scalar                  sensor max range
``min_range``       float64 scalar                  sensor min range
``grid``            float64 ``(ndim + 1 + 2,)``     optional: ``shape..., resolution, ox, oy``
``truth``           bool/int/float, ``grid.shape``  optional: ground-truth map (needs ``grid``)
``settings``        str (JSON object)               how the data were made / read
``provenance``      str (JSON object)               where they came from
==================  ==============================  =============================================

Writes are atomic (:func:`ogm_ppl.io.atomic_write`). :func:`load_dataset`
checks everything and raises :class:`DatasetFileError` naming the file, what is wrong and a hint.

>>> import tempfile, os
>>> from ogm_ppl import Scans
>>> s = Scans([0.0, 0.0, 0.0], [0.0], [1.0], max_range=4.0)
>>> p = os.path.join(tempfile.mkdtemp(), "d.npz")
>>> load_dataset(save_dataset(p, s, settings={"source": "doc"})).settings
{'source': 'doc'}
"""

from __future__ import annotations

import json
import math
import os
import zipfile
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ogm_ppl.grid import Grid
from ogm_ppl.io import atomic_write
from ogm_ppl.scans import Scans

__all__ = [
    "FORMAT",
    "FORMAT_VERSION",
    "Dataset",
    "DatasetFileError",
    "load_dataset",
    "save_dataset",
]

FORMAT = "ogm_ppl.dataset"
FORMAT_VERSION = 1
_REQUIRED = (
    "format",
    "format_version",
    "poses",
    "angles",
    "ranges",
    "valid",
    "max_range",
    "min_range",
    "settings",
    "provenance",
)
#: settings the library reads back as numbers (the simulation's range noise in cells, used by `ogm-ppl map`)
_NUMERIC_SETTINGS = ("sigma_cells",)
_HINT = "was it written by ogm_ppl.datasets.save_dataset?"
_KINDS = {"f": "float", "U": "string", "iu": "integer", "b": "bool"}


class DatasetFileError(ValueError):
    """A dataset file that cannot be read: the message names the path, the problem and a hint."""

    def __init__(self, path: str | os.PathLike, problem: str, hint: str = _HINT) -> None:
        self.path, self.problem, self.hint = str(path), problem, hint
        super().__init__(f"{self.path}: {problem} (hint: {hint})")


@dataclass(frozen=True)
class Dataset:
    """The contents of a dataset file."""

    scans: Scans
    grid: Grid | None = None
    truth: np.ndarray | None = None
    settings: dict | None = None
    provenance: dict | None = None


def _json(value: dict | None, name: str) -> str:
    if value is not None and not isinstance(value, dict):
        raise TypeError(f"save_dataset: {name} must be a dict or None, got {type(value).__name__}")
    try:
        return json.dumps(value if value is not None else {}, allow_nan=False, sort_keys=True)
    except (TypeError, ValueError) as e:
        raise TypeError(f"save_dataset: {name} must be JSON-serialisable ({e})") from None


def save_dataset(
    path: str | os.PathLike,
    scans: Scans,
    *,
    grid: Grid | None = None,
    truth: np.ndarray | None = None,
    settings: dict | None = None,
    provenance: dict | None = None,
) -> Path:
    """Write a dataset file atomically (format in the module docstring); returns the path written.

    ``truth`` (a map of ``grid.shape``) needs ``grid``; ``settings`` and ``provenance`` are JSON dicts.
    The file is written exactly at ``path`` (no ``.npz`` is appended).
    """
    if not isinstance(scans, Scans):
        raise TypeError(f"save_dataset: scans must be a Scans, got {type(scans).__name__}")
    if grid is not None and not isinstance(grid, Grid):
        raise TypeError(f"save_dataset: grid must be a Grid or None, got {type(grid).__name__}")
    assert scans.valid is not None  # Scans.__post_init__ always sets the S x B mask
    arrays: dict[str, np.ndarray] = {
        "format": np.array(FORMAT),
        "format_version": np.array(FORMAT_VERSION, dtype=np.int64),
        "poses": scans.poses,
        "angles": scans.angles,
        "ranges": scans.ranges,
        "valid": scans.valid,
        "max_range": np.array(scans.max_range),
        "min_range": np.array(scans.min_range),
        "settings": np.array(_json(settings, "settings")),
        "provenance": np.array(_json(provenance, "provenance")),
    }
    if grid is not None:
        arrays["grid"] = np.array([*grid.shape, grid.resolution, *grid.origin], dtype=float)
    if truth is not None:
        truth = np.asarray(truth)
        if grid is None or truth.shape != grid.shape:
            raise ValueError(f"save_dataset: truth must have the grid's shape, got {truth.shape}")
        if truth.dtype.kind not in "biuf":
            raise ValueError(f"save_dataset: truth must be bool or numeric, got {truth.dtype}")
        arrays["truth"] = truth
    path = Path(path)
    with atomic_write(path) as f:
        # numpy's stub: **kwds might also bind its `allow_pickle: bool`; our keys are array names
        np.savez_compressed(f, **arrays)  # type: ignore[arg-type]
    return path


def _read_arrays(path: Path) -> dict[str, np.ndarray]:
    size = path.stat().st_size  # FileNotFoundError for a missing file, as open() would
    if size == 0:
        raise DatasetFileError(path, "the file is empty (0 bytes)", "an interrupted copy?")
    with open(path, "rb") as f:
        magic = f.read(4)
    if magic[:2] == b"\x1f\x8b":
        raise DatasetFileError(path, "is gzip data, not an npz dataset", "a CARMEN log? use read_carmen")
    if magic != b"PK\x03\x04":
        raise DatasetFileError(path, "is not an npz file (no zip signature)", _HINT)
    try:
        with np.load(path, allow_pickle=False) as npz:
            return {k: npz[k] for k in npz.files}
    except ValueError as e:
        if "pickle" in str(e):
            raise DatasetFileError(path, "holds object (pickled) arrays, which are refused", _HINT) from None
        raise DatasetFileError(path, f"is corrupt ({e})", "re-create or re-copy the file") from None
    except (zipfile.BadZipFile, zlib.error, EOFError, OSError, KeyError) as e:
        raise DatasetFileError(
            path,
            f"is truncated or corrupt ({type(e).__name__}: {e})",
            "re-create or re-copy the file",
        ) from None


def _scalar(path: Path, a: dict, key: str, kind: str) -> Any:  # the Python scalar (str, int, float, bool)
    v = a[key]
    if v.shape != () or v.dtype.kind not in kind:
        raise DatasetFileError(path, f"entry {key!r} must be a {_KINDS[kind]} scalar, got {v.dtype} {v.shape}")
    return v.item()


def _dict(path: Path, a: dict, key: str) -> dict:
    text = _scalar(path, a, key, "U")
    try:
        value = json.loads(text)
    except json.JSONDecodeError as e:
        raise DatasetFileError(path, f"entry {key!r} is not valid JSON ({e})") from None
    if not isinstance(value, dict):
        raise DatasetFileError(path, f"entry {key!r} must be a JSON object, got {type(value).__name__}")
    return value


def load_dataset(path: str | os.PathLike) -> Dataset:
    """Read and validate a dataset file written by :func:`save_dataset`.

    Raises:
        DatasetFileError: the file is empty, not an npz, truncated, someone else's npz, another
            format version, or has missing / malformed entries (the message says which).
        FileNotFoundError: there is no such file.
    """
    path = Path(path)
    a = _read_arrays(path)
    if "format" not in a:
        raise DatasetFileError(path, f"is not an ogm_ppl dataset (no 'format' entry; entries: {sorted(a)[:8]})")
    fmt = _scalar(path, a, "format", "U")
    if fmt != FORMAT:
        raise DatasetFileError(path, f"has format {fmt!r}, expected {FORMAT!r}")
    if "format_version" not in a:
        raise DatasetFileError(path, "has no 'format_version' entry")
    version = _scalar(path, a, "format_version", "iu")
    if version != FORMAT_VERSION:
        raise DatasetFileError(
            path,
            f"has format version {version}; this ogm_ppl reads version {FORMAT_VERSION}",
            "use the ogm_ppl version that wrote it, or re-create the file",
        )
    missing = [k for k in _REQUIRED if k not in a]
    if missing:
        raise DatasetFileError(path, f"lacks the entries {missing}")
    for key, kind in (("poses", "f"), ("angles", "f"), ("ranges", "f"), ("valid", "b")):
        if a[key].dtype.kind != kind or a[key].ndim != 2:
            raise DatasetFileError(
                path,
                f"entry {key!r} must be a 2D {_KINDS[kind]} array, got {a[key].dtype} {a[key].shape}",
            )
    grid = None
    if "grid" in a:
        g = a["grid"]
        if g.dtype.kind != "f" or g.shape not in ((4,), (5,)) or not np.all(np.isfinite(g)):
            raise DatasetFileError(path, f"entry 'grid' must hold shape, resolution, origin; got {g!r}")
        try:
            grid = Grid(tuple(g[:-3].tolist()), float(g[-3]), (float(g[-2]), float(g[-1])))
        except ValueError as e:
            raise DatasetFileError(path, f"entry 'grid' is not a valid grid ({e})") from None
    truth = a.get("truth")
    if truth is not None:
        if grid is None or truth.shape != grid.shape or truth.dtype.kind not in "biuf":
            raise DatasetFileError(
                path,
                f"entry 'truth' must be a bool/numeric map of the grid's shape, got {truth.dtype} {truth.shape}",
            )
        if truth.dtype.kind == "f" and not np.all(np.isfinite(truth)):
            raise DatasetFileError(path, "entry 'truth' has non-finite values")
    if a["poses"].shape[0] == 0:
        raise DatasetFileError(path, "entry 'poses' holds no scans (0 rows)", "a dataset needs at least one scan")
    try:
        scans = Scans(
            a["poses"],
            a["angles"],
            a["ranges"],
            _scalar(path, a, "max_range", "f"),
            valid=a["valid"],
            min_range=_scalar(path, a, "min_range", "f"),
        )
    except ValueError as e:
        if isinstance(e, DatasetFileError):
            raise
        raise DatasetFileError(path, f"holds invalid scans: {e}") from None
    settings = _dict(path, a, "settings")
    for key in _NUMERIC_SETTINGS:
        v = settings.get(key)
        if v is not None and (isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v) or v <= 0):
            raise DatasetFileError(path, f"entry 'settings', field {key!r} must be a number > 0 or null, got {v!r}")
    return Dataset(scans, grid, truth, settings, _dict(path, a, "provenance"))
