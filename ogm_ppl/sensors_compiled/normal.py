r"""The standard normal's bin masses and upper tail, as the compiled reading models use them.

* :func:`phi_diff` ``(lo, hi)`` — :math:`\Phi(hi) - \Phi(lo)` for ``lo <= hi`` (either may be infinite),
  from ``erfc`` on the side of zero where it is accurate;
* :func:`tail` ``(x)`` — :math:`Q(x) = 1 - \Phi(x)` for ``x >= 0`` by cubic Hermite interpolation of
  :math:`\log Q` on a ``1/512`` grid (relative error below ``1e-13``; four times cheaper than ``erfc``),
  ``erfc`` beyond ``x = 10``.

Both are numba functions compiled inline into the kernels that call them (and callable from Python).
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

__all__ = ["LOG_SQRT_2PI", "SQRT2", "phi_diff", "tail"]

SQRT2 = math.sqrt(2.0)
LOG_SQRT_2PI = 0.5 * math.log(2.0 * math.pi)


def _log_tail_table(step: int = 512, top: float = 10.0) -> tuple[np.ndarray, np.ndarray]:
    """``log Q(x)`` and its derivative ``-phi(x) / Q(x)`` at ``x = i / step``, ``0 <= x <= top``
    (``Q = 1 - Phi``, the normal upper tail), for :func:`tail`."""
    x = np.arange(int(top * step) + 2) / step
    q = np.array([0.5 * math.erfc(v / SQRT2) for v in x])
    phi = np.exp(-0.5 * x * x - LOG_SQRT_2PI)
    return np.log(q), -phi / q


_TAIL_STEP = 512
_LOGQ, _DLOGQ = _log_tail_table(_TAIL_STEP)
_TAIL_TOP = (len(_LOGQ) - 2) / _TAIL_STEP


@nb.njit(cache=True, inline="always")
def phi_diff(lo, hi):
    """``Phi(hi) - Phi(lo)`` for ``lo <= hi`` (either may be infinite), accurate in both tails."""
    if lo > 0.0:
        return 0.5 * (math.erfc(lo / SQRT2) - math.erfc(hi / SQRT2))
    if hi < 0.0:
        return 0.5 * (math.erfc(-hi / SQRT2) - math.erfc(-lo / SQRT2))
    return 1.0 - 0.5 * (math.erfc(-lo / SQRT2) + math.erfc(hi / SQRT2))


@nb.njit(cache=True, inline="always")
def tail(x):
    """``Q(x) = 1 - Phi(x)`` for ``x >= 0`` (module docstring)."""
    if x >= _TAIL_TOP:
        return 0.5 * math.erfc(x / SQRT2)
    u = x * _TAIL_STEP
    i = int(u)
    t = u - i
    h = 1.0 / _TAIL_STEP
    t2 = t * t
    t3 = t2 * t
    y = (
        (2.0 * t3 - 3.0 * t2 + 1.0) * _LOGQ[i]
        + (t3 - 2.0 * t2 + t) * h * _DLOGQ[i]
        + (3.0 * t2 - 2.0 * t3) * _LOGQ[i + 1]
        + (t3 - t2) * h * _DLOGQ[i + 1]
    )
    return math.exp(y)
