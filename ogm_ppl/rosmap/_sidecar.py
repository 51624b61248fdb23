"""The ``<stem>.npz`` sidecar of a map: its exact float probabilities, unknown mask and grid, tied to the
image by its SHA-256."""

from __future__ import annotations

import hashlib
import io
import warnings
from pathlib import Path

import numpy as np

from ogm_ppl.grid import Grid
from ogm_ppl.rosmap._errors import RosMapError
from ogm_ppl.rosmap._yaml import RosMapSettings

FORMAT_VERSION = 1


def _sidecar_bytes(p: np.ndarray, unknown: np.ndarray, grid: Grid, image_bytes: bytes) -> bytes:
    """The sidecar of a map whose image is ``image_bytes`` (format version :data:`FORMAT_VERSION`)."""
    buf = io.BytesIO()
    np.savez_compressed(  # a map's probabilities repeat (the prior's value where unobserved): zip shrinks them
        buf,
        format_version=np.int64(FORMAT_VERSION),
        probabilities=p,
        unknown=unknown,
        shape=np.asarray(grid.shape, dtype=np.int64),
        resolution=np.float64(grid.resolution),
        origin=np.asarray(grid.origin, dtype=np.float64),
        image_sha256=np.str_(hashlib.sha256(image_bytes).hexdigest()),
    )
    return buf.getvalue()


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
