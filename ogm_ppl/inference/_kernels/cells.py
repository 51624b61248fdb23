"""First hits of rays and the from-scratch likelihood ratio of a cell (Sections 2.2, 4.1.2).

Per ray, ``f[r]`` is the kappa of its first occupied cell (its length when none). The log-likelihood
change of flipping cell ``k`` costs only the rays through ``k`` (the transposed index); rays already
blocked before ``k`` are skipped (Section 4.1.2). The sweeps keep these sums instead
(:mod:`~ogm_ppl.inference._kernels.cell_sweep`); :func:`cell_log_lik_ratio` is the plain sum they are
tested against.
"""

from __future__ import annotations

import numba as nb
import numpy as np


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
def gather_as_float(m, idx):
    """``m[idx]`` as float64 (a chain's state at its latent cells, the sample a kernel returns): one pass,
    against numpy's fancy index and cast, which make two."""
    out = np.empty(idx.shape[0], np.float64)
    for i in range(idx.shape[0]):
        out[i] = m[idx[i]]
    return out
