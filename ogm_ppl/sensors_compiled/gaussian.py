r"""The compiled reading model of :class:`~ogm_ppl.sensors.GaussianRange`: :class:`GaussianReading`.

In the continuous kappa coordinate (:mod:`ogm_ppl.sensors`: a range ``r`` reads ``z = r + 1/2``, a first hit
entered at ``t`` cells sits at ``f = t + 1/2``, the max range is censored at ``F + 1/2``), with ``Phi`` the
standard normal CDF, for a first hit on the ray

.. math::
    p(z \mid f) = (1 - p_{rand})\,\mathcal{N}(z; f, \sigma^2) + \frac{p_{rand}}{F + 1}
    \quad (-\tfrac12 \le z \le F + \tfrac12), \qquad
    P(\text{max} \mid f) = (1 - p_{rand})\,\Bigl(1 - \Phi\bigl(\tfrac{F + 1/2 - f}{\sigma}\bigr)\Bigr),

the normal part extending below ``-1/2``; with no occupied cell on the ray (``none``) the reading is max range
with probability ``1 - p_rand`` and uniform on ``[-1/2, F + 1/2]`` otherwise. The hit outcomes are the range
bins of ``width`` cells, edges ``-1/2 + j width`` (``j = 1..J-1``), the first bin open to ``-inf``, the last
ending at ``F + 1/2``: ``J = ceil((F + 1) / width)``. A bin's probability is a difference of the normal CDF
(:func:`~ogm_ppl.sensors_compiled.normal.phi_diff`) plus the uniform part by length; a bin farther than 38
standard deviations from ``f`` gets no normal mass (it underflows below ``1e-300``), and :func:`gaussian_fill_row`
evaluates the normal part only on the bins within 8.5 standard deviations (beyond, a bin's mass is below
``1e-17``), from one tabulated tail per bin edge (:func:`~ogm_ppl.sensors_compiled.normal.tail`).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from ogm_ppl._numba_cache import njit_shipped
from ogm_ppl.sensors_compiled.normal import LOG_SQRT_2PI, SQRT2, phi_diff, tail
from ogm_ppl.sensors_compiled.registry import register

__all__ = [
    "GaussianReading",
    "gaussian_bin_prob",
    "gaussian_coord",
    "gaussian_draw",
    "gaussian_fill_row",
    "gaussian_log_reading",
    "gaussian_num_outcomes",
]

_FAR = 38.0  # |standardised distance| beyond which a normal bin mass underflows (< 1e-300)
_WINDOW = 8.5  # bins farther than this many sigma from a first hit get no Gaussian mass (< 1e-17)


class GaussianReading(NamedTuple):
    """Gaussian range noise ``sigma`` (cells) with a share ``p_rand`` of uniform random readings, ranges
    quantised into bins of ``width`` cells (module docstring)."""

    sigma: float
    p_rand: float
    width: float


@njit_shipped(inline="always")
def gaussian_num_outcomes(reading, F):
    """``J = ceil((F + 1) / width)`` range bins (to ``1e-12``, so a whole number of bins is not rounded up)."""
    return math.ceil((F + 1.0) / reading.width - 1e-12)


@njit_shipped(inline="always")
def gaussian_bin_prob(reading, j, J, f, none, F):
    """``P(outcome j | f)``: bin ``j < J`` or max range ``j = J`` (module docstring)."""
    sigma, p_rand, width = reading.sigma, reading.p_rand, reading.width
    if j == J:
        if none:
            return 1.0 - p_rand
        return (1.0 - p_rand) * 0.5 * math.erfc((F + 0.5 - f) / (sigma * SQRT2))
    a = -0.5 + j * width
    b = min(-0.5 + (j + 1) * width, F + 0.5)
    unif = p_rand * (b - a) / (F + 1.0) if p_rand > 0.0 else 0.0
    if none:
        return unif
    hi = (b - f) / sigma
    lo = -np.inf if j == 0 else (a - f) / sigma
    if lo > _FAR or hi < -_FAR:
        return unif
    return (1.0 - p_rand) * phi_diff(lo, hi) + unif


@njit_shipped(inline="always")
def gaussian_fill_row(reading, row, J, f, none, F, tails):
    """``row[j] = P(outcome j | f)`` for ``j = 0..J``, the normal part on the bins within 8.5 standard
    deviations of ``f`` only, one tabulated tail per bin edge (``tails``: scratch of ``J + 2``)."""
    sigma, p_rand, width = reading.sigma, reading.p_rand, reading.width
    if none:
        for j in range(J + 1):
            row[j] = gaussian_bin_prob(reading, j, J, f, none, F)
        return
    for j in range(J):
        a = -0.5 + j * width
        b = min(-0.5 + (j + 1) * width, F + 0.5)
        row[j] = p_rand * (b - a) / (F + 1.0) if p_rand > 0.0 else 0.0
    row[J] = (1.0 - p_rand) * 0.5 * math.erfc((F + 0.5 - f) / (sigma * SQRT2))
    lo = max(0, math.floor((f - _WINDOW * sigma + 0.5) / width))
    hi = min(J - 1, math.floor((f + _WINDOW * sigma + 0.5) / width))
    if hi < lo:
        return
    # edges lo..hi+1 as signed standardised distances; tails[k] = the smaller tail mass at edge k
    for k in range(lo, hi + 2):
        if k == 0:
            tails[k] = 0.0
        else:
            e = F + 0.5 if k == J else -0.5 + k * width
            x = (e - f) / sigma
            tails[k] = tail(abs(x))
    for j in range(lo, hi + 1):
        xa = -np.inf if j == 0 else (-0.5 + j * width - f) / sigma
        eb = F + 0.5 if j + 1 == J else -0.5 + (j + 1) * width
        xb = (eb - f) / sigma
        if xa > 0.0:
            g = tails[j] - tails[j + 1]
        elif xb < 0.0:
            g = tails[j + 1] - tails[j]
        else:
            g = 1.0 - tails[j] - tails[j + 1]
        row[j] += (1.0 - p_rand) * max(g, 0.0)


@njit_shipped(inline="always")
def gaussian_log_reading(reading, binned, y, jb, is_max, J, f, none, F):
    """``log p(reading | f)``: the log density of the range ``y`` (or the log max-range probability), or the
    log-probability of bin ``jb`` when ``binned``."""
    sigma, p_rand = reading.sigma, reading.p_rand
    if binned:
        v = gaussian_bin_prob(reading, jb, J, f, none, F)
        return math.log(v) if v > 0.0 else -np.inf
    if is_max:
        v = (1.0 - p_rand) if none else (1.0 - p_rand) * 0.5 * math.erfc((F + 0.5 - f) / (sigma * SQRT2))
        return math.log(v) if v > 0.0 else -np.inf
    lu = -np.inf
    if p_rand > 0.0 and y >= -0.5 and y <= F + 0.5:
        lu = math.log(p_rand / (F + 1.0))
    if none:
        return lu
    d = (y - f) / sigma
    lg = -0.5 * d * d - math.log(sigma) - LOG_SQRT_2PI
    if p_rand > 0.0:
        lg += math.log1p(-p_rand)
        m = max(lg, lu)
        return m + math.log(math.exp(lg - m) + math.exp(lu - m))
    return lg


@njit_shipped(inline="always")
def gaussian_coord(reading, t_enter, off, kap):
    """The continuous kappa ``t + 1/2`` of the cell at ``kap``."""
    return t_enter[off + kap] + 0.5


@njit_shipped(inline="always")
def gaussian_draw(reading, J, f, none, F, u_a, u_b, e):
    """A reading as :meth:`GaussianRange.sample <ogm_ppl.sensors.GaussianRange.sample>` draws it: uniform on
    ``[-1/2, F + 1/2]`` if ``u_a < p_rand``, else max range (``none``) or ``f + sigma e``, max range beyond
    ``F + 1/2``; ``(y, is_max, bin)``."""
    y = 0.0
    is_max = False
    if reading.p_rand > 0.0 and u_a < reading.p_rand:
        y = -0.5 + (F + 1.0) * u_b
    elif none:
        is_max = True
    else:
        y = f + reading.sigma * e
        is_max = y > F + 0.5
    if is_max:
        jb = J
    else:
        jb = min(max(math.floor((y + 0.5) / reading.width), 0), J - 1)
    return y, is_max, jb


register(
    GaussianReading,
    num_outcomes=gaussian_num_outcomes,
    bin_prob=gaussian_bin_prob,
    fill_row=gaussian_fill_row,
    log_reading=gaussian_log_reading,
    coord=gaussian_coord,
    draw=gaussian_draw,
    continuous=True,
)
