"""What every compiled bundle's transforms share: tempering (``beta log p~``) and a bias (``log p~ + h sum m``)
of log-potential arrays with ``-inf`` (a forbidden configuration) kept, and the crop of per-cell arrays to a
window."""

from __future__ import annotations

import numpy as np

__all__ = ["check_beta", "check_bias", "crop_cells", "scaled", "shifted"]


def check_beta(beta) -> float:
    """``beta`` as a float, checked: finite and ``>= 0``."""
    b = float(beta)
    if not (np.isfinite(b) and b >= 0.0):
        raise ValueError(f"a tempering exponent beta must be finite and >= 0, got {beta!r}")
    return b


def check_bias(bias) -> float:
    """``bias`` as a float, checked: finite."""
    h = float(bias)
    if not np.isfinite(h):
        raise ValueError(f"a bias must be finite, got {bias!r}")
    return h


def shifted(x: np.ndarray, add) -> np.ndarray:
    """``x + add`` for the finite entries of ``x``; infinite entries stay as they are."""
    return np.where(np.isfinite(x), x + add, x)


def scaled(x: np.ndarray, beta: float) -> np.ndarray:
    """``beta * x`` for the finite entries of ``x``; infinite entries (``log 0 = -inf``, hard constraints)
    stay as they are, so ``beta = 0`` gives ``0`` on the support and keeps ``-inf`` off it."""
    out = np.array(x, dtype=np.float64, order="C")  # a copy
    finite = np.isfinite(out)
    out[finite] *= beta
    return out


def crop_cells(a: np.ndarray, grid_cols: int, r0: int, c0: int, rows: int, cols: int) -> np.ndarray:
    """The per-cell array ``a`` (row-major, ``grid_cols`` wide) cropped to ``rows x cols`` cells at ``(r0, c0)``."""
    return np.ascontiguousarray(np.asarray(a).reshape(-1, grid_cols)[r0 : r0 + rows, c0 : c0 + cols].reshape(-1))
