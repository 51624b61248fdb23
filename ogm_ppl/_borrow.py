"""Borrowed array views for compiled hot loops: the same arrays, without numba's reference counting.

numba counts the references of every array it holds (an atomic add on the array's ``meminfo``) each time
a value holding one is copied: in particular every time an inlined function takes it as an argument. A
sweep that calls a prior's conditional and the likelihood's kept sums once a cell thus pays a pair of
atomic operations per array of each bundle per cell; numba's reference-count pruning does not remove them
once the inlined body branches. On the 500 x 500 reference scene those pairs cost more than the
conditional itself.

:func:`borrow` returns a value of the same numba type whose arrays (at any depth of tuples and named
tuples) point to the same data but carry no ``meminfo``, so that counting their references does nothing.
A kernel borrows its arguments once on entry; the caller keeps the originals alive for the whole call.

**Contract.** A borrowed value must not outlive the call that borrowed it: never return it (nor an
array taken from it) to Python and never store it where it outlives the call. Writes through it are
writes to the original arrays.
"""

from __future__ import annotations

from numba.core import cgutils, types
from numba.extending import intrinsic

__all__ = ["borrow"]


def _borrowed(context, builder, ty, val):
    if isinstance(ty, types.Array):
        src = context.make_array(ty)(context, builder, val)
        out = context.make_array(ty)(context, builder)
        for name in ("nitems", "itemsize", "data", "shape", "strides"):
            setattr(out, name, getattr(src, name))
        out.meminfo = cgutils.get_null_value(out.meminfo.type)
        out.parent = cgutils.get_null_value(out.parent.type)
        return out._getvalue()
    if isinstance(ty, types.BaseTuple):
        items = [_borrowed(context, builder, t, builder.extract_value(val, i)) for i, t in enumerate(ty)]
        return context.make_tuple(builder, ty, items)
    # anything else is returned as a new reference, as an intrinsic's result must be
    if context.enable_nrt:
        context.nrt.incref(builder, ty, val)
    return val


@intrinsic
def borrow(typingctx, x):
    """``x`` (an array, or a tuple / named tuple holding arrays at any depth; other values pass through)
    with every array's reference count detached; see the module docstring for the contract."""

    def codegen(context, builder, signature, args):
        return _borrowed(context, builder, signature.args[0], args[0])

    return x(x), codegen
