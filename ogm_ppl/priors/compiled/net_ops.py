"""The arithmetic every compiled net-field function shares (:mod:`~ogm_ppl.priors.compiled.net_field`): the
hidden units' activation sums, a window's pre-activation read from the map, and a stack scratch array."""

from __future__ import annotations

import numba as nb
import numpy as np
from llvmlite import ir
from numba.core import cgutils, types
from numba.extending import intrinsic
from numba.np.arrayobj import make_array, populate_array

__all__ = ["ACTIVATIONS", "MAX_NET_WINDOW", "MAX_UNITS", "act_shift", "act_sum", "stack_f64", "window_pre"]

#: the hidden units' nonlinearities, by code: ``relu(x) = max(x, 0)``, ``softplus(x) = log(1 + e^x)``
ACTIVATIONS: tuple[str, ...] = ("relu", "softplus")
#: the most hidden units a bundle may have (the stack scratch of a conditional: ``MAX_UNITS`` float64)
MAX_UNITS = 512
#: the largest window side
MAX_NET_WINDOW = 9


@intrinsic
def stack_f64(typingctx, n):
    """A C-contiguous float64 array of the literal length ``n`` on the stack of the calling function (allocated
    once in its entry block; no numba runtime, so callable from loops compiled with ``_nrt=False``)."""
    if not isinstance(n, types.IntegerLiteral):
        return None
    size = int(n.literal_value)
    arrty = types.Array(types.float64, 1, "C")

    def codegen(context, builder, signature, args):
        ptr = cgutils.alloca_once(builder, ir.DoubleType(), size=size)
        ary = make_array(arrty)(context, builder)
        intp = context.get_value_type(types.intp)
        populate_array(ary, data=ptr, shape=[intp(size)], strides=[intp(8)], itemsize=intp(8), meminfo=None)
        return ary._getvalue()

    return arrty(n), codegen


@nb.njit(cache=True, inline="always")
def _softplus(x):
    """``log(1 + e^x)``, stable for large ``|x|``."""
    return max(x, 0.0) + np.log1p(np.exp(-abs(x)))


@nb.njit(cache=True, inline="always")
def act_sum(pre, o, out, U, act):
    """``sum_u out[u] sigma(pre[o + u])``."""
    s = 0.0
    if act == 0:
        for u in range(U):
            s += out[u] * max(pre[o + u], 0.0)
    else:
        for u in range(U):
            s += out[u] * _softplus(pre[o + u])
    return s


@nb.njit(cache=True, inline="always")
def act_shift(pre, o, wt, p, sign, out, U, act):
    """``sum_u out[u] (sigma(pre[o + u] + sign wt[p + u]) - sigma(pre[o + u]))``: a window's change when the cell
    at its weight column ``p`` turns occupied (``sign = 1``) or free (``sign = -1``)."""
    s = 0.0
    if act == 0:
        for u in range(U):
            x = pre[o + u]
            s += out[u] * (max(x + sign * wt[p + u], 0.0) - max(x, 0.0))
    else:
        for u in range(U):
            x = pre[o + u]
            s += out[u] * (_softplus(x + sign * wt[p + u]) - _softplus(x))
    return s


@nb.njit(cache=True, inline="always")
def window_pre(nf, m, r0, c0, skip, buf, o):
    """``buf[o : o + U] = b + sum_j W[:, j] x_j`` over the window anchored at ``(r0, c0)``, cell ``skip`` (a grid
    id, or -1) read as free, cells past the edge as ``pad``."""
    U, w, R, C = nf.units, nf.w, nf.rows, nf.cols
    wt = nf.wt
    for u in range(U):
        buf[o + u] = nf.bias[u]
    if r0 >= 0 and c0 >= 0 and r0 + w <= R and c0 + w <= C:
        for i in range(w):
            row = (r0 + i) * C + c0
            for j in range(w):
                kk = row + j
                if m[kk] and kk != skip:
                    p = (i * w + j) * U
                    for u in range(U):
                        buf[o + u] += wt[p + u]
        return
    pad = nf.pad
    for i in range(w):
        r = r0 + i
        for j in range(w):
            c = c0 + j
            p = (i * w + j) * U
            if 0 <= r < R and 0 <= c < C:
                kk = r * C + c
                if m[kk] and kk != skip:
                    for u in range(U):
                        buf[o + u] += wt[p + u]
            elif pad != 0.0:
                for u in range(U):
                    buf[o + u] += pad * wt[p + u]
