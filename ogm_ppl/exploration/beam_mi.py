r"""The per-beam mutual information ``I(f_r; z_r)`` of every candidate ray, compiled once per reading kind.

A reading depends on the map only through the beam's first hit ``f`` (:mod:`ogm_ppl.exploration.information`),
so with ``p_k = p(f_r = k)`` (:mod:`~ogm_ppl.exploration.first_hits`, column ``len_r``: no occupied cell on
the ray) and the sensor's outcome probabilities ``P(j | k)`` (``j = 0..J``, the compiled reading model of
:mod:`ogm_ppl.sensors_compiled`: ``fill_row``),

.. math::
    I(f_r; z_r) = \sum_k \sum_j p_k P(j \mid k) \log \frac{P(j \mid k)}{q_j}, \qquad
    q_j = \sum_k p_k P(j \mid k),

in nats. First hits of probability ``<= 1e-15`` are left out (they change it by less than ``1e-13`` bits), and
a ray with one first hit left carries no information.
"""

from __future__ import annotations

import math

import numpy as np

from ogm_ppl._numba_cache import njit_shipped
from ogm_ppl.exploration.rays import RayTable
from ogm_ppl.sensors_compiled import coord, fill_row, num_outcomes

__all__ = ["NEGLIGIBLE", "beam_mi_kernel"]

NEGLIGIBLE = 1e-15  # first hits of smaller probability are left out of the per-beam sum (< 1e-13 bits)


# cached on disk for the shipped reading kinds only: a kind of one's own compiles once per process (numba's cache
# index pickles every bundle type; ogm_ppl._numba_cache)
@njit_shipped
def beam_mi_kernel(pf, rays: RayTable, Fray, reading):
    """``I(f_r; z_r)`` in nats for every ray ``r`` (``R`` float64) from its first-hit distribution
    ``pf[r, :len_r + 1]`` (``R x (Lmax + 1)``), on rays whose last kappa is ``Fray[r]``, under the reading
    model of the bundle ``reading``."""
    offsets, t_enter = rays.offsets, rays.t_enter
    R = offsets.shape[0] - 1
    out = np.zeros(R)
    for r in range(R):
        n = offsets[r + 1] - offsets[r]
        F = Fray[r]
        J = num_outcomes(reading, F)
        ns = 0
        for kap in range(n + 1):
            if pf[r, kap] > NEGLIGIBLE:
                ns += 1
        if ns <= 1:
            continue  # a certain first hit carries no information
        rows = np.empty((ns, J + 1))
        tails = np.empty(J + 2)
        ps = np.empty(ns)
        q = np.zeros(J + 1)
        i = 0
        for kap in range(n + 1):
            p = pf[r, kap]
            if p <= NEGLIGIBLE:
                continue
            none = kap == n
            f = 0.0 if none else coord(reading, t_enter, offsets[r], kap)
            fill_row(reading, rows[i], J, f, none, F, tails)
            for j in range(J + 1):
                q[j] += p * rows[i, j]
            ps[i] = p
            i += 1
        mi = 0.0
        for i in range(ns):
            for j in range(J + 1):
                pv = ps[i] * rows[i, j]
                # q[j] sums such products, so q[j] >= pv > 0 here; a product that underflows to 0 (a max-range
                # probability of 1e-320 times its first hit's) adds nothing and is skipped, as q[j] may be 0
                if pv > 0.0:
                    mi += pv * math.log(rows[i, j] / q[j])
        out[r] = max(mi, 0.0)
    return out
