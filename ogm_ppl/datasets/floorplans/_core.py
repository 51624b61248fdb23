"""What every floor-plan corpus shares: the plan record, where the corpora live, the split rule, format errors and
the steps that turn classified cells into an occupancy grid (downsample, crop, outside).

Coordinates: a plan's arrays are ``H x W`` with row 0 at the top of the source image (or, for the vector
corpora, at the smallest ``y`` of the source coordinates, which also grow downwards).
"""

from __future__ import annotations

import hashlib
import os
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

__all__ = [
    "MAX_PLAN_CELLS",
    "TEST_EVERY",
    "CorpusNotFoundError",
    "FloorPlan",
    "PlanFormatError",
    "corpus_path",
    "finish",
    "floorplan_root",
    "hash_split",
    "natural_key",
    "rasterise",
]

#: a building is held out when the first 8 hex digits of its hash are divisible by this (about 1 in 5)
TEST_EVERY = 5
#: largest grid a vector plan is drawn on (cells); a larger one is refused naming the plan (a wrong scale)
MAX_PLAN_CELLS = 50_000_000


@dataclass(frozen=True, eq=False)
class FloorPlan:
    """One rasterised plan. ``occupancy``, ``known``: ``H x W`` bool (``True`` = occupied / known).

    ``resolution`` is metres per cell, or ``None`` where the corpus has no metric scale (DungeonMaps).
    Where ``known`` is False the occupancy value is meaningless (set to False).
    """

    name: str
    corpus: str
    occupancy: np.ndarray
    known: np.ndarray
    resolution: float | None
    building: str
    split: str

    @property
    def shape(self) -> tuple[int, int]:
        return (int(self.occupancy.shape[0]), int(self.occupancy.shape[1]))

    @property
    def occupied_fraction(self) -> float:
        """Share of known cells that are occupied."""
        return float(self.occupancy[self.known].mean()) if self.known.any() else float("nan")


class CorpusNotFoundError(FileNotFoundError):
    """A floor-plan corpus is not where :func:`floorplan_root` looks; the message says where it looked and how to
    point the library at the data."""


class PlanFormatError(ValueError):
    """A corpus file is malformed. The message names the file, the line (where the format has lines) and the
    field: ``FILE:LINE: FIELD: PROBLEM``; the parts are kept as ``path``, ``line``, ``field``, ``problem``."""

    def __init__(self, path: str | os.PathLike, problem: str, *, field: str | None = None, line: int | None = None):
        self.path, self.problem, self.field, self.line = str(path), problem, field, line
        where = f"{path}:{line}" if line is not None else str(path)
        super().__init__(f"{where}: {field}: {problem}" if field else f"{where}: {problem}")


def floorplan_root(root: str | os.PathLike | None = None) -> Path:
    """``root``, else ``$OGM_PPL_FLOORPLANS``, else ``$OGM_PPL_DATA/floorplans`` (the shared data folder), else
    ``shared/data/floorplans`` beside the repository of a source checkout. The folder need not exist (a plan file
    is then compared with no corpus); reading a corpus from a missing folder raises :class:`CorpusNotFoundError`."""
    if root is not None:
        return Path(root)
    env = os.environ.get("OGM_PPL_FLOORPLANS")
    if env:
        return Path(env)
    data = os.environ.get("OGM_PPL_DATA")
    if data:
        return Path(data) / "floorplans"
    return Path(__file__).resolve().parents[4] / "shared" / "data" / "floorplans"


def corpus_path(path: Path, corpus: str) -> Path:
    """``path`` (a corpus's folder or archive) if it exists, else :class:`CorpusNotFoundError`."""
    if not path.exists():
        raise CorpusNotFoundError(
            f"{path}: the {corpus} floor-plan corpus is not there; set $OGM_PPL_DATA to the shared data folder "
            "(the one holding floorplans/) or $OGM_PPL_FLOORPLANS to the corpora's folder"
        )
    return path


def natural_key(s: str) -> list:
    """Sort key: digit runs compare as numbers (``map2`` before ``map10``)."""
    return [int(t) if t.isdigit() else t for t in re.split(r"(\d+)", s)]


def hash_split(salt: str, building: str) -> str:
    """``"test"`` if ``int(sha256("<salt>:<building>")[:8], 16) % 5 == 0``, else ``"train"`` (about 80/20, fixed
    by the building alone, so every floor and variant of a building falls on the same side)."""
    h = int(hashlib.sha256(f"{salt}:{building}".encode()).hexdigest()[:8], 16)
    return "test" if h % TEST_EVERY == 0 else "train"


# -- from classified cells to the grid ---------------------------------------------------------------------------
def _block_any(a: np.ndarray, f: int) -> np.ndarray:
    """``a`` (``h f x w f`` bool) -> ``h x w``: whether any element of each ``f x f`` block is set (an OR of the
    blocks' ``f`` rows, then of their ``f`` columns: ``2 f`` array operations, several times faster than
    ``reshape(h, f, w, f).any((1, 3))``)."""
    H, W = a.shape
    rows = a.reshape(H // f, f, W)
    r = rows[:, 0].copy()
    for i in range(1, f):
        r |= rows[:, i]
    cols = r.reshape(H // f, W // f, f)
    out = cols[..., 0].copy()
    for i in range(1, f):
        out |= cols[..., i]
    return out


def _downsample(occ: np.ndarray, free: np.ndarray, f: int) -> tuple[np.ndarray, np.ndarray]:
    if f == 1:
        return occ, free
    H, W = occ.shape
    h, w = -(-H // f), -(-W // f)
    pad = ((0, h * f - H), (0, w * f - W))
    o = _block_any(np.pad(occ, pad), f)
    fr = _block_any(np.pad(free, pad), f)
    return o, fr & ~o


def _crop(occ: np.ndarray, free: np.ndarray, margin: int | None) -> tuple[np.ndarray, np.ndarray]:
    if margin is None or not free.any():
        return occ, free
    rows, cols = np.flatnonzero(free.any(1)), np.flatnonzero(free.any(0))
    r0, r1, c0, c1 = (
        rows[0] - margin,
        rows[-1] + 1 + margin,
        cols[0] - margin,
        cols[-1] + 1 + margin,
    )
    H, W = occ.shape
    pad = ((max(0, -r0), max(0, r1 - H)), (max(0, -c0), max(0, c1 - W)))
    occ, free = np.pad(occ, pad), np.pad(free, pad)
    r0, c0 = r0 + pad[0][0], c0 + pad[1][0]
    r1, c1 = r1 + pad[0][0], c1 + pad[1][0]
    return occ[r0:r1, c0:c1], free[r0:r1, c0:c1]


def _outside(occ: np.ndarray, free: np.ndarray, wall_cells: int) -> np.ndarray:
    """Non-free cells connected to the map's edge and more than ``wall_cells`` from free space."""
    from scipy import ndimage

    solid = ~free
    labels, _ = ndimage.label(solid, structure=np.ones((3, 3), dtype=bool))
    edge = np.unique(np.concatenate([labels[0], labels[-1], labels[:, 0], labels[:, -1]]))
    touching = np.isin(labels, edge[edge > 0])
    near = (
        ndimage.binary_dilation(free, structure=np.ones((3, 3), dtype=bool), iterations=wall_cells)
        if wall_cells > 0
        else free
    )
    return touching & ~near


def _check_outside(outside: str) -> None:
    if outside not in ("occupied", "unknown"):
        raise ValueError(f"outside must be 'occupied' or 'unknown', got {outside!r}")


def rasterise(
    occ_px: np.ndarray,
    free_px: np.ndarray,
    factor: int = 1,
    margin: int | None = 20,
    wall_cells: int = 2,
    outside: str = "occupied",
) -> tuple[np.ndarray, np.ndarray]:
    """Steps 2-5 of :mod:`ogm_ppl.datasets.floorplans`'s docstring on classified pixels -> ``(occupancy, known)``:
    downsample by ``factor`` (a cell is occupied if any pixel is), crop to the free space plus ``margin`` cells,
    mark the exterior (non-free, connected to the edge, over ``wall_cells`` from free space) and make unknown
    cells occupied (``outside="occupied"``) or leave them unknown."""
    _check_outside(outside)
    occ, free = _downsample(np.asarray(occ_px, bool), np.asarray(free_px, bool) & ~np.asarray(occ_px, bool), factor)
    occ, free = _crop(occ, free, margin)
    unknown = ~(occ | free) | _outside(occ, free, wall_cells)
    if outside == "occupied":
        return ~free, np.ones(free.shape, dtype=bool)
    return occ & ~unknown, ~unknown


def finish(occ: np.ndarray, free: np.ndarray, margin: int | None, outside: str) -> tuple[np.ndarray, np.ndarray]:
    """Cells already classified (occupied, free, the rest unknown: a vector plan's outside) -> ``(occupancy,
    known)``: cropped to the free space plus ``margin`` cells (padding with unknown), then every unknown cell made
    occupied (``outside="occupied"``) or left unknown (``"unknown"``)."""
    _check_outside(outside)
    occ, free = _crop(np.asarray(occ, bool), np.asarray(free, bool) & ~np.asarray(occ, bool), margin)
    if outside == "occupied":
        return ~free, np.ones(free.shape, dtype=bool)
    return occ.copy(), occ | free
