"""Compiled single-cell updates of the forward-model likelihood (Sections 2.2, 4.1.2).

State: the map ``m`` (uint8, ``K``) and, per ray, the kappa ``f[r]`` of its first occupied cell (its
length when none). The log-likelihood change of flipping cell ``k`` costs only the rays through ``k``
(the transposed index); rays already blocked before ``k`` are skipped (Section 4.1.2). When the first
occupied cell of a ray is freed, the next one is found by scanning on along the ray.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from ogm_ppl.priors.local import cell_log_odds


@nb.njit(cache=True)
def first_hits(m, offsets, cells):
    """``f[r]`` for every ray of the CSR structure."""
    R = offsets.shape[0] - 1
    f = np.empty(R, np.int64)
    for r in range(R):
        n = offsets[r + 1] - offsets[r]
        f[r] = n
        for j in range(n):
            if m[cells[offsets[r] + j]]:
                f[r] = j
                break
    return f


@nb.njit(cache=True, inline="always")
def _next_occupied(m, offsets, cells, r, start):
    a = offsets[r]
    n = offsets[r + 1] - a
    for j in range(start, n):
        if m[cells[a + j]]:
            return j
    return n


@nb.njit(cache=True)
def cell_log_lik_ratio(k, m, f, offsets, cells, c_off, c_ray, c_kappa, ll):
    """``log p(z | m_k = 1, m_-k) - log p(z | m_k = 0, m_-k)`` (Eq. 2.4, 4.2)."""
    d = 0.0
    for p in range(c_off[k], c_off[k + 1]):
        r = c_ray[p]
        kap = c_kappa[p]
        fr = f[r]
        if fr < kap:
            continue  # blocked before k: m_k does not matter to this ray
        f0 = fr if fr > kap else _next_occupied(m, offsets, cells, r, kap + 1)
        t = ll[r, kap] - ll[r, f0]
        if t == t:  # both impossible (-inf - -inf): no preference
            d += t
    return d


@nb.njit(cache=True)
def set_cell(k, v, m, f, offsets, cells, c_off, c_ray, c_kappa):
    """Set ``m[k] = v`` and update the first hits of the rays through ``k``."""
    if m[k] == v:
        return
    m[k] = v
    for p in range(c_off[k], c_off[k + 1]):
        r = c_ray[p]
        kap = c_kappa[p]
        if v:
            if kap < f[r]:
                f[r] = kap
        elif f[r] == kap:
            f[r] = _next_occupied(m, offsets, cells, r, kap + 1)


@nb.njit(cache=True, inline="always")
def _icm_set(k, lo, m, f, offsets, cells, c_off, c_ray, c_kappa) -> int:
    """ICM's step for cell ``k`` with conditional log-odds ``lo``: set it to its more likely value (keep
    it on a tie); returns 1 if it changed."""
    v = m[k]
    if lo > 0.0:
        v = 1
    elif lo < 0.0:
        v = 0
    if v == m[k]:
        return 0
    set_cell(k, v, m, f, offsets, cells, c_off, c_ray, c_kappa)
    return 1


@nb.njit(cache=True)
def icm_sweeps(order, prior_log_odds, m, f, offsets, cells, c_off, c_ray, c_kappa, ll, max_sweeps):
    """Iterated conditional modes (the EM hill-climbing of Section 2.2) over ``order``.

    Each cell takes the value with the larger conditional posterior (ties keep the current value),
    until a sweep changes nothing. Returns the number of sweeps run.
    """
    for s in range(max_sweeps):
        changed = 0
        for i in range(order.shape[0]):
            k = order[i]
            lo = prior_log_odds[k] + cell_log_lik_ratio(k, m, f, offsets, cells, c_off, c_ray, c_kappa, ll)
            changed += _icm_set(k, lo, m, f, offsets, cells, c_off, c_ray, c_kappa)
        if changed == 0:
            return s + 1
    return max_sweeps


@nb.njit(cache=True)
def local_icm_sweeps(order, lp, m, f, offsets, cells, c_off, c_ray, c_kappa, ll, max_sweeps):
    """:func:`icm_sweeps` with a correlated prior's local log-odds (``ogm_ppl.priors.local``)."""
    for s in range(max_sweeps):
        changed = 0
        for i in range(order.shape[0]):
            k = order[i]
            lo = cell_log_odds(lp, k, m)  # inlined
            lo += cell_log_lik_ratio(k, m, f, offsets, cells, c_off, c_ray, c_kappa, ll)
            changed += _icm_set(k, lo, m, f, offsets, cells, c_off, c_ray, c_kappa)
        if changed == 0:
            return s + 1
    return max_sweeps
