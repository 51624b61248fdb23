"""Compiled loops over a reading bundle's registered functions, for the sensor contract (numba compiles them
once per reading kind, inlining the kind's functions as the exploration kernels do)."""

from __future__ import annotations

import numba as nb
import numpy as np

from ogm_ppl.sensors_compiled import bin_prob, draw, fill_row, log_reading, num_outcomes

__all__ = ["compiled_draws", "compiled_log_readings", "compiled_rows"]


@nb.njit
def compiled_log_readings(reading, binned, ys, outcomes, maxes, f, none, F):
    """``log p(reading_i | f)`` for readings ``ys[i]`` (continuous ranges) or ``outcomes[i]`` (the outcome;
    ``maxes[i]``: max range, outcome ``J``) on a ray with last kappa ``F``."""
    J = num_outcomes(reading, F)
    out = np.empty(ys.shape[0])
    for i in range(ys.shape[0]):
        jb = J if maxes[i] else outcomes[i]
        out[i] = log_reading(reading, binned, ys[i], jb, maxes[i], J, f, none, F)
    return out


@nb.njit
def compiled_rows(reading, f, none, F):
    """``(by_bin, filled)``: ``P(outcome j | f)`` for ``j = 0..J`` from ``bin_prob`` and from ``fill_row``."""
    J = num_outcomes(reading, F)
    by_bin = np.empty(J + 1)
    for j in range(J + 1):
        by_bin[j] = bin_prob(reading, j, J, f, none, F)
    filled = np.empty(J + 1)
    tails = np.empty(J + 2)
    fill_row(reading, filled, J, f, none, F, tails)
    return by_bin, filled


@nb.njit
def compiled_draws(reading, f, none, F, u_a, u_b, e):
    """The outcomes (``0..J``) of the readings ``draw`` gives from the random numbers ``u_a, u_b, e`` (``N``
    each), and the ranges it draws (``N``)."""
    J = num_outcomes(reading, F)
    n = u_a.shape[0]
    jbs = np.empty(n, np.int64)
    ys = np.empty(n)
    for i in range(n):
        y, is_max, jb = draw(reading, J, f, none, F, u_a[i], u_b[i], e[i])
        jbs[i] = J if is_max else jb
        ys[i] = y
    return jbs, ys
