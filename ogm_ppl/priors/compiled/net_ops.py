"""The arithmetic every compiled net-field function shares (:mod:`~ogm_ppl.priors.compiled.net_field`): the
hidden units' activation sums, a window's pre-activation read from the map, and stack scratch arrays."""

from __future__ import annotations

import numpy as np
from llvmlite import ir
from numba.core import cgutils, types
from numba.extending import intrinsic
from numba.np.arrayobj import make_array, populate_array

from ogm_ppl._numba_cache import njit_shipped

__all__ = [
    "ACTIVATIONS",
    "MAX_NET_WINDOW",
    "MAX_UNITS",
    "act_shift",
    "act_sum",
    "fresh_log_odds",
    "softplus",
    "stack_f64",
    "stack_i64",
    "window_pre",
]

#: the hidden units' nonlinearities, by code: ``relu(x) = max(x, 0)``, ``softplus(x) = log(1 + e^x)``
ACTIVATIONS: tuple[str, ...] = ("relu", "softplus")
#: the most hidden units a bundle may have (the stack scratch of a conditional: ``MAX_UNITS`` float64)
MAX_UNITS = 512
#: the largest window side
MAX_NET_WINDOW = 9


def _stack_array(dtype, ir_type, n):
    """The typing and codegen of a C-contiguous ``dtype`` array of the literal length ``n`` on the caller's stack."""
    if not isinstance(n, types.IntegerLiteral):
        return None
    size = int(n.literal_value)
    arrty = types.Array(dtype, 1, "C")

    def codegen(context, builder, signature, args):
        ptr = cgutils.alloca_once(builder, ir_type, size=size)
        ary = make_array(arrty)(context, builder)
        intp = context.get_value_type(types.intp)
        populate_array(ary, data=ptr, shape=[intp(size)], strides=[intp(8)], itemsize=intp(8), meminfo=None)
        return ary._getvalue()

    return arrty(n), codegen


@intrinsic
def stack_f64(typingctx, n):
    """A C-contiguous float64 array of the literal length ``n`` on the stack of the calling function (allocated
    once in its entry block; no numba runtime, so callable from loops compiled with ``_nrt=False``)."""
    return _stack_array(types.float64, ir.DoubleType(), n)


@intrinsic
def stack_i64(typingctx, n):
    """:func:`stack_f64` for int64."""
    return _stack_array(types.int64, ir.IntType(64), n)


@njit_shipped(inline="always")
def softplus(x):
    """``log(1 + e^x)``, stable for large ``|x|``."""
    return max(x, 0.0) + np.log1p(np.exp(-abs(x)))


@njit_shipped(inline="always")
def act_sum(pre, o, out, U, act):
    """``sum_u out[u] sigma(pre[o + u])``."""
    s = 0.0
    if act == 0:
        for u in range(U):
            s += out[u] * max(pre[o + u], 0.0)
    else:
        for u in range(U):
            s += out[u] * softplus(pre[o + u])
    return s


@njit_shipped(inline="always")
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
            s += out[u] * (softplus(x + sign * wt[p + u]) - softplus(x))
    return s


@njit_shipped(inline="always")
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


@njit_shipped(_nrt=False)
def fresh_log_odds(nf, k, m):
    """``log p~(m_k = 1, m_-k) - log p~(m_k = 0, m_-k)`` of a net field, each of the cell's ``w^2`` windows read
    afresh from the map (:mod:`~ogm_ppl.priors.compiled.net_field`). Allocates nothing (``U`` floats of stack)."""
    buf = stack_f64(MAX_UNITS)
    C, w, U = nf.cols, nf.w, nf.units
    r = k // C
    c = k - r * C
    lo = nf.unary
    for a in range(w):
        for b in range(w):
            window_pre(nf, m, r - a, c - b, k, buf, 0)
            lo += act_shift(buf, 0, nf.wt, (a * w + b) * U, 1.0, nf.out, U, nf.act)
    return lo
