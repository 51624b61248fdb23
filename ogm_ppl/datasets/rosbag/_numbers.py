"""float32 message fields as float64: shortest decimals and angles ``p * pi / q`` (the *Beams* rule of
:mod:`ogm_ppl.datasets.rosbag`)."""

from __future__ import annotations

import math
from fractions import Fraction

import numpy as np

_MAX_DENOMINATOR = 1440  # pi / 1440 = 0.125 degrees
_ANGLE_CACHE: dict[float, float] = {}


def _widen(v: float, widen: str) -> float:
    """A float32 value as float64: its shortest decimal (``"decimal"``) or itself (``"binary"``)."""
    f = np.float32(v)
    return float(f) if widen == "binary" or not np.isfinite(f) else float(str(f))


def _angle64(v: float, widen: str) -> float:
    """A float32 angle as float64: ``p * pi / q`` when its float32 rounding is ``v`` (``q <= 1440``),
    else :func:`_widen` (:mod:`ogm_ppl.datasets.rosbag`)."""
    key = float(v)
    hit = _ANGLE_CACHE.get(key)
    if hit is not None and widen == "decimal":
        return hit
    out = _widen(v, widen)
    if widen == "decimal" and math.isfinite(key):
        fr = Fraction(key / math.pi).limit_denominator(_MAX_DENOMINATOR)
        cand = fr.numerator * math.pi / fr.denominator
        if np.float32(cand) == np.float32(key):
            out = cand
        if len(_ANGLE_CACHE) < 10_000:
            _ANGLE_CACHE[key] = out
    return out


def _widen_array(a: np.ndarray, widen: str) -> np.ndarray:
    """float32 values as float64: themselves (``"binary"``) or their shortest decimal (``"decimal"``): the
    decimal of ``d = 1..9`` significant digits nearest to the value, for the smallest ``d`` whose float32
    rounding is the value (what ``str(np.float32(v))`` prints). Vectorised over ``d`` for magnitudes
    ``1e-13 .. 1e14``, where every power of ten used is exact in float64 and so the rounding is exact;
    other values go through the string."""
    f = np.asarray(a, dtype=np.float32)
    shape = f.shape
    f = f.ravel()
    with np.errstate(invalid="ignore"):  # signalling NaN payloads
        x = f.astype(np.float64)
    if widen == "binary":
        return x.reshape(shape)
    out = x.copy()
    with np.errstate(all="ignore"):
        e_all = np.floor(np.log10(np.abs(x)))
    fast = np.isfinite(x) & (x != 0) & (e_all >= -13) & (e_all <= 13)
    idx = np.flatnonzero(fast)
    xs, fs = x[idx], f[idx]
    e = e_all[idx].astype(np.int64)
    res, done = xs.copy(), np.zeros(len(idx), dtype=bool)
    for d in range(1, 10):
        k = d - 1 - e  # round to k decimals: |k| <= 21, 10^|k| exact
        p10 = 10.0 ** np.abs(k)
        with np.errstate(all="ignore"):
            y = np.where(k >= 0, np.round(xs * p10) / p10, np.round(xs / p10) * p10)
        ok = ~done & (y.astype(np.float32) == fs)
        res[ok], done = y[ok], done | ok
        if done.all():
            break
    res[~done] = fs[~done].astype(str).astype(np.float64)  # not reached: 9 digits always round-trip
    out[idx] = res
    other = np.isfinite(x) & (x != 0) & ~fast
    if other.any():
        out[other] = f[other].astype(str).astype(np.float64)
    return out.reshape(shape)
