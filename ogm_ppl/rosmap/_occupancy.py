"""Probabilities <-> ``nav_msgs/OccupancyGrid`` values, and map_server's reading of an image's pixels (the
formulas of :mod:`ogm_ppl.rosmap`)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Literal

import numpy as np

from ogm_ppl.rosmap._yaml import RosMapSettings

#: ``(occupied_thresh, free_thresh)`` of the two conventions: ROS 1 ``map_saver`` and Nav2 ``map_saver``.
THRESHOLDS: dict[str, tuple[float, float]] = {"ros1": (0.65, 0.196), "nav2": (0.65, 0.25)}
_FREE, _OCCUPIED, _UNKNOWN = 254, 0, 205  # map_saver's trinary bytes (before negate)


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
