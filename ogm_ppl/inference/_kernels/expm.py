"""``exp(x)`` for ``x <= 0`` in a form LLVM vectorises: the exponentials of the choice step
(:mod:`~ogm_ppl.inference._kernels.choice`), which a scalar ``math.exp`` call per configuration made a
large share of a patch update.

``exp(x) = 2^k exp(r)`` with ``k = round(x / ln 2)`` (by the ``1.5 * 2^52`` shifter, whose low bits then
hold ``k`` as an integer: no float-to-int conversion, which AVX2 lacks), ``r = x - k ln 2`` in two parts
(fdlibm's ``ln2_hi`` / ``ln2_lo``; ``|r| <= ln 2 / 2``), ``exp(r)`` by its Taylor polynomial of degree 13
(truncation below ``4e-18`` relative) in Horner form with fused multiply-adds, and ``2^k`` built from its
bits. Relative error about one ulp against numpy's ``exp`` (``tests/inference/_kernels/test_expm.py``).
Arguments below ``-708`` (near where ``2^k`` would be subnormal), ``-inf`` and NaN give 0: the choice step
divides by a sum that contains ``exp(0) = 1``, so such terms are below its rounding.
"""

from __future__ import annotations

import math

import numba as nb
from llvmlite import ir
from numba.core import types
from numba.extending import intrinsic

__all__ = ["exp_nonpos"]

_LOG2E = 1.4426950408889634
_LN2_HI = 6.93147180369123816490e-01
_LN2_LO = 1.90821492927058770002e-10
_SHIFTER = 6755399441055744.0  # 1.5 * 2^52
_MIN_X = -708.0
_C = tuple(1.0 / math.factorial(i) for i in range(14))
_C2, _C3, _C4, _C5, _C6, _C7, _C8, _C9, _C10, _C11, _C12, _C13 = _C[2:]


@intrinsic
def _f64_from_bits(typingctx, i):
    sig = types.float64(types.int64)

    def codegen(context, builder, signature, args):
        return builder.bitcast(args[0], ir.DoubleType())

    return sig, codegen


@intrinsic
def _bits_of_f64(typingctx, x):
    sig = types.int64(types.float64)

    def codegen(context, builder, signature, args):
        return builder.bitcast(args[0], ir.IntType(64))

    return sig, codegen


# Not numba-inlined: LLVM inlines it into the caller's loop and keeps its fused multiply-adds ("contract"
# is an instruction flag), which numba's own inlining would lower with the caller's flags instead.
@nb.njit(cache=True, fastmath={"contract"})
def exp_nonpos(x: float) -> float:
    """``exp(x)`` for ``x <= 0`` (0 for ``x < -708``, ``-inf`` and NaN); branch-free, so loops vectorise."""
    xc = x if x >= _MIN_X else _MIN_X
    kd = xc * _LOG2E + _SHIFTER
    kb = _bits_of_f64(kd)
    k = kd - _SHIFTER
    r = (xc - k * _LN2_HI) - k * _LN2_LO
    p = _C13
    p = p * r + _C12
    p = p * r + _C11
    p = p * r + _C10
    p = p * r + _C9
    p = p * r + _C8
    p = p * r + _C7
    p = p * r + _C6
    p = p * r + _C5
    p = p * r + _C4
    p = p * r + _C3
    p = p * r + _C2
    p = p * r + 1.0
    p = p * r + 1.0
    y = p * _f64_from_bits((kb + 1023) << 52)
    return y if x >= _MIN_X else 0.0
