"""Pose samples of a pose topic interpolated at the scan stamps, and the ``pose_tolerance`` rule that
brackets each stamp (the *Poses* rule of :mod:`ogm_ppl.datasets.rosbag`)."""

from __future__ import annotations

import numpy as np


def _bracket(samples: np.ndarray, t: np.ndarray, tol_ns: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """For each stamp ``t``: the last sample ``i0`` at or before it, the first ``i1`` at or after it,
    the weight ``w = (t - s[i0]) / (s[i1] - s[i0])`` (0 when they coincide) and whether both lie within
    ``tol_ns``. ``samples`` sorted (int64 ns)."""
    n = len(samples)
    i1 = np.searchsorted(samples, t, side="left")
    i0 = np.searchsorted(samples, t, side="right") - 1
    ok = (i0 >= 0) & (i1 < n)
    i0c, i1c = np.clip(i0, 0, max(n - 1, 0)), np.clip(i1, 0, max(n - 1, 0))
    if n:
        s0, s1 = samples[i0c], samples[i1c]
        ok &= (t - s0 <= tol_ns) & (s1 - t <= tol_ns)
        span = (s1 - s0).astype(np.float64)
        with np.errstate(all="ignore"):
            w = np.where(span > 0, (t - s0).astype(np.float64) / np.where(span > 0, span, 1.0), 0.0)
    else:
        w = np.zeros(len(t))
    return i0c, i1c, w, ok


def _poses_from_topic(samples: list, stamps: np.ndarray, tol_ns: int, offset) -> tuple[np.ndarray, np.ndarray]:
    """Laser poses ``S x 3`` at ``stamps`` and which scans have one (:mod:`ogm_ppl.datasets.rosbag`)."""
    if not samples:
        return np.zeros((len(stamps), 3)), np.zeros(len(stamps), dtype=bool)
    arr = sorted(samples, key=lambda s: s[0])
    st = np.array([s[0] for s in arr], dtype=np.int64)
    p = np.array([s[1:] for s in arr], dtype=np.float64)
    i0, i1, w, ok = _bracket(st, stamps, tol_ns)
    p0, p1 = p[i0], p[i1]
    dyaw = np.mod(p1[:, 2] - p0[:, 2] + np.pi, 2 * np.pi) - np.pi
    out = np.empty((len(stamps), 3))
    out[:, :2] = p0[:, :2] + w[:, None] * (p1[:, :2] - p0[:, :2])
    out[:, 2] = p0[:, 2] + w * dyaw
    ox, oy, oyaw = offset
    if ox or oy or oyaw:
        c, s = np.cos(out[:, 2]), np.sin(out[:, 2])
        out[:, 0] += ox * c - oy * s
        out[:, 1] += ox * s + oy * c
        out[:, 2] += oyaw
    return out, ok
