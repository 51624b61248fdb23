r"""The compiled reading model of :class:`~ogm_ppl.sensors.PatternMatch`: :class:`PatternReading`.

The outcomes are the ``J = F + 1`` kappas ``0..F`` of the ray and max range (outcome ``J``). The outcome that
matches the first hit (``z = f``, or max range when no cell of the ray is occupied) has probability
``p_occ``; the other ``F + 1`` share ``1 - p_occ`` equally:

.. math:: P(z \mid f) = p_{occ} \text{ if } z = f, \quad (1 - p_{occ}) / (F + 1) \text{ otherwise.}
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from ogm_ppl._numba_cache import njit_shipped
from ogm_ppl.sensors_compiled.registry import register

__all__ = [
    "PatternReading",
    "pattern_bin_prob",
    "pattern_coord",
    "pattern_draw",
    "pattern_log_reading",
    "pattern_num_outcomes",
]


class PatternReading(NamedTuple):
    """The pattern-matching model with probability ``p_occ`` of the matching outcome (module docstring)."""

    p_occ: float


@njit_shipped(inline="always")
def pattern_num_outcomes(reading, F):
    """``J = F + 1`` hit outcomes (kappa ``0..F``)."""
    return int(F) + 1


@njit_shipped(inline="always")
def pattern_bin_prob(reading, j, J, f, none, F):
    """``P(outcome j | f)``: ``p_occ`` for the matching outcome, ``(1 - p_occ) / (F + 1)`` for the others."""
    p_occ = reading.p_occ
    other = (1.0 - p_occ) / (F + 1.0)
    if j == J:
        return p_occ if none else other
    if (not none) and j == int(f):
        return p_occ
    return other


@njit_shipped(inline="always")
def pattern_log_reading(reading, binned, y, jb, is_max, J, f, none, F):
    """``log P(outcome jb | f)`` (a discrete sensor's readings are outcomes, binned or not)."""
    v = pattern_bin_prob(reading, jb, J, f, none, F)
    return math.log(v) if v > 0.0 else -np.inf


@njit_shipped(inline="always")
def pattern_coord(reading, t_enter, off, kap):
    """The cell's kappa."""
    return float(kap)


@njit_shipped(inline="always")
def pattern_draw(reading, J, f, none, F, u_a, u_b, e):
    """An outcome as :meth:`PatternMatch.sample <ogm_ppl.sensors.PatternMatch.sample>` draws it: the matching
    one if ``u_a < p_occ``, else one of the ``F + 1`` others, uniform by ``u_b``; ``(0.0, False, outcome)``."""
    truth = J if none else int(f)
    if u_a < reading.p_occ:
        jb = truth
    else:
        u = min(math.floor(u_b * (F + 1.0)), int(F))
        jb = u + 1 if u >= truth else u
    return 0.0, False, jb


register(
    PatternReading,
    num_outcomes=pattern_num_outcomes,
    bin_prob=pattern_bin_prob,
    log_reading=pattern_log_reading,
    coord=pattern_coord,
    draw=pattern_draw,
    continuous=False,
)
