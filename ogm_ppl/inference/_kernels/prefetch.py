"""A software prefetch for compiled kernels: ``prefetch(arr, i, j)`` asks the CPU to bring the cache line
of ``arr[i, j]`` (a 2D C-contiguous array) towards its caches without waiting for it (LLVM
``llvm.prefetch``, read, high locality). It reads nothing and never faults, so an index past the end is
harmless; a kernel issues it where it learns an address it will read after other work (e.g. a patch
update's rows of the likelihood table, which lie far apart in memory)."""

from __future__ import annotations

from llvmlite import ir
from numba.core import cgutils, types
from numba.extending import intrinsic

__all__ = ["prefetch"]


@intrinsic
def prefetch(typingctx, arr, i, j):
    """Prefetch the line of ``arr[i, j]``."""
    if not (isinstance(arr, types.Array) and arr.ndim == 2 and arr.layout == "C"):
        return None

    def codegen(context, builder, signature, args):
        aryty = signature.args[0]
        ary = context.make_array(aryty)(context, builder, args[0])
        ptr = cgutils.get_item_pointer(context, builder, aryty, ary, [args[1], args[2]], wraparound=False)
        i8p = ir.IntType(8).as_pointer()
        fnty = ir.FunctionType(ir.VoidType(), [i8p, ir.IntType(32), ir.IntType(32), ir.IntType(32)])
        fn = cgutils.get_or_insert_function(builder.module, fnty, "llvm.prefetch.p0")
        i32 = ir.IntType(32)
        builder.call(fn, [builder.bitcast(ptr, i8p), i32(0), i32(3), i32(1)])
        return context.get_dummy_value()

    return types.void(arr, types.intp, types.intp), codegen
