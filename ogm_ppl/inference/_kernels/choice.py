"""The choice step of a patch update, shared by every patch kernel and the Python generic path: a
heat-bath draw (Algorithm 1), Liu's metropolised Gibbs, and the Metropolis-Hastings test of Algorithm 2's
random configuration. (The single-cell kernels' binary version is ``cell_sweep.new_value``.)"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from ogm_ppl.inference._kernels.expm import exp_nonpos

__all__ = ["accept_random", "categorical", "categorical_table", "choose", "metropolised_pick", "pick_from_table"]


@nb.njit(cache=True, inline="always")
def _exp_weights(logw, n, ew, skip):
    """``ew[j] = exp(logw[j] - max logw)`` for ``j < n`` (:func:`~ogm_ppl.inference._kernels.expm.exp_nonpos`);
    returns ``(sum, sum without entry skip)``, each summed directly in index order (no cancellation), or
    ``(-1, -1)`` if no entry has mass."""
    mx = -np.inf
    for j in range(n):
        if logw[j] > mx:
            mx = logw[j]
    if mx == -np.inf:
        return -1.0, -1.0
    for j in range(n):  # vectorised (exp_nonpos); the sums below stay in index order
        ew[j] = exp_nonpos(logw[j] - mx)
    total = 0.0
    other = 0.0
    for j in range(n):
        e = ew[j]
        total += e
        if j != skip:
            other += e
    return total, other


@nb.njit(cache=True)
def categorical(logw, W, u, ew):
    """Index drawn by inverse CDF from ``softmax(logw[:W])`` with the uniform ``u`` (``-1`` if no entry
    has mass); ``ew`` (``>= W``) holds the exponentials, so each is computed once."""
    total, _ = _exp_weights(logw, W, ew, -1)
    if total < 0.0:
        return -1
    t = u * total
    acc = 0.0
    for w in range(W):
        acc += ew[w]
        if t < acc:
            return w
    for w in range(W - 1, -1, -1):  # rounding: the last configuration with mass
        if logw[w] > -np.inf:
            return w
    return -1


@nb.njit(cache=True)
def categorical_table(logw, W, acc):
    """The inverse-CDF table of :func:`categorical` over ``softmax(logw[:W])``, for draws with many uniforms:
    ``acc[w]`` the running sums of the exponentials (the same sums, in the same order, as :func:`categorical`
    accumulates). Returns ``(total, last)``: the sum and the last index with mass (``(-1, -1)`` if none)."""
    total, _ = _exp_weights(logw, W, acc, -1)
    if total < 0.0:
        return -1.0, np.int64(-1)
    a = 0.0
    for w in range(W):
        a += acc[w]
        acc[w] = a
    last = np.int64(-1)
    for w in range(W - 1, -1, -1):
        if logw[w] > -np.inf:
            last = np.int64(w)
            break
    return total, last


@nb.njit(cache=True, inline="always")
def pick_from_table(acc, total, last, W, u):
    """:func:`categorical`'s draw with the uniform ``u`` from its table (:func:`categorical_table`), by binary
    search: the first ``w`` with ``u total < acc[w]`` (else ``last``), the index the linear scan returns."""
    t = u * total
    lo, hi = 0, W
    while lo < hi:
        mid = (lo + hi) >> 1
        if t < acc[mid]:
            hi = mid
        else:
            lo = mid + 1
    return lo if lo < W else last


@nb.njit(cache=True)
def metropolised_pick(logw, n, jc, u_choice, u_accept, ew):
    """Liu's metropolised Gibbs over ``n`` candidates with the current one at index ``jc``: propose
    ``j != jc`` with probability ``p_j / (1 - p_jc)`` and accept with ``min(1, (1 - p_jc) / (1 - p_j))``,
    which leaves ``p`` invariant and moves at least as often as a heat-bath draw (Peskun's order).

    ``p = softmax(logw[:n])``; ``jc = -1`` (the current configuration is not a candidate: it has no prior
    mass) falls back to a heat-bath draw. Returns the chosen index (``jc`` when staying; ``-1`` if no
    candidate has mass). ``ew`` (``>= n``) is scratch.
    """
    if jc < 0:
        return categorical(logw, n, u_choice, ew)
    total, other = _exp_weights(logw, n, ew, jc)
    if total < 0.0:
        return -1
    if other == 0.0:
        return jc  # no other configuration has mass
    t = u_choice * other
    acc = 0.0
    pick = -1
    for j in range(n):
        if j == jc or ew[j] == 0.0:
            continue
        pick = j  # (rounding: the last one with mass)
        acc += ew[j]
        if t < acc:
            break
    denom = other + ew[jc] - ew[pick]  # = total - e_pick, so the ratio is (1 - p_jc) / (1 - p_pick)
    if denom <= 0.0 or u_accept * denom < other:
        return pick
    return jc


@nb.njit(cache=True, inline="always")
def choose(logw, n, jc, u_choice, u_accept, metropolised, ew):
    """The next configuration's index among ``n`` weighed ones (current: ``jc``, ``-1`` if not among
    them): :func:`metropolised_pick` if ``metropolised``, else a heat-bath draw; ``-1`` if none has mass."""
    if metropolised:
        return metropolised_pick(logw, n, jc, u_choice, u_accept, ew)
    return categorical(logw, n, u_choice, ew)


@nb.njit(cache=True, inline="always")
def accept_random(lw_cur, lw_prop, u_accept):
    """Metropolis-Hastings test of Algorithm 2's uniformly proposed configuration: accept with
    ``min(1, p(prop) / p(cur))``; a current state without mass is always left."""
    d = lw_prop - lw_cur
    return lw_cur == -np.inf or d >= 0.0 or (d > -np.inf and u_accept < math.exp(d))
