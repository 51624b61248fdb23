"""Numba's ``inline="always"`` without its quadratic copy of the callee's IR: one memo for all of a callee's blocks,
and one copy instead of two.

Before inlining a callee, numba (``numba.core.inline_closurecall.InlineWorker.inline_ir``) deep-copies the callee's
IR one block at a time, each block with a fresh ``copy.deepcopy`` memo. Every variable holds the function's one
:class:`numba.core.ir.Scope`, which holds every variable of the function, so each block copies the whole scope
again: ``blocks x variables`` work per inlined call, and a callee that has itself inlined others (a sweep loop that
inlines a prior's conditional and a state update that inlines its ray walk) is large in both. In the library's
single-cell sweep this copying was about two thirds of the compile time of each specialisation (36.8 s of CPU for
``cell_sweep.sweep`` with independent cells; 17.1 s with one memo).

:func:`install` replaces that method by numba's own source with two changes: the blocks are copied with one memo,
so the copy keeps the aliasing of the original (all blocks share one scope copy, as all blocks of the original share
one scope) and each object is copied once; and the "unmutated copy" of the callee that the method returns (and both
of numba's callers drop) is the callee as passed in, not a second copy (a further ~9%: 17.4 s -> 15.9 s). Everything
else numba does is unchanged; the compiled code is the same (``tests/test__numba_inline.py`` compares the LLVM IR
numba writes with and without it). If numba's source is not the one this was written against, nothing is replaced
(:data:`INSTALLED` stays ``False``), and ``OGM_PPL_NUMBA_INLINE_PATCH=0`` in the environment leaves numba untouched.
The replacement is process-wide: it also applies to other code's ``inline="always"`` functions compiled after
``ogm_ppl`` is imported, until numba copies a callee once itself.
"""

from __future__ import annotations

import inspect
import os
import textwrap

from numba.core import inline_closurecall

__all__ = ["INSTALLED", "ORIGINAL_INLINE_IR", "install"]

#: numba's own ``InlineWorker.inline_ir``
ORIGINAL_INLINE_IR = inline_closurecall.InlineWorker.inline_ir

_PER_BLOCK = """        for block_label, block in the_ir.blocks.items():
            new_block = copy.deepcopy(the_ir.blocks[block_label])
"""
_ONE_MEMO = """        memo = {}
        for block_label, block in the_ir.blocks.items():
            new_block = copy.deepcopy(the_ir.blocks[block_label], memo)
"""
# numba then copies the copy (before mutating it) to return "an unmutated copy" of the callee, which both of numba's
# callers drop; the callee as passed in is that unmutated IR, so it is returned instead of a second copy
_COPY = """    callee_ir = copy_ir(callee_ir)
"""
_KEEP_AND_COPY = """    callee_ir_original = callee_ir
    callee_ir = copy_ir(callee_ir)
"""
_SECOND_COPY = """    callee_ir_original = copy_ir(callee_ir)
"""

#: whether :func:`install` replaced numba's method
INSTALLED = False


def install() -> bool:
    """Replace ``InlineWorker.inline_ir`` by numba's source with one deep-copy memo per copied IR (module
    docstring); returns whether it did (``False`` when numba's source differs from the expected one)."""
    global INSTALLED
    if INSTALLED:
        return True
    if os.environ.get("OGM_PPL_NUMBA_INLINE_PATCH", "1") == "0":  # numba's own inliner, untouched
        return False
    try:
        source = textwrap.dedent(inspect.getsource(ORIGINAL_INLINE_IR))
    except (OSError, TypeError):  # no source shipped
        return False
    if any(source.count(part) != 1 for part in (_PER_BLOCK, _COPY, _SECOND_COPY)):
        return False
    source = source.replace(_PER_BLOCK, _ONE_MEMO).replace(_SECOND_COPY, "").replace(_COPY, _KEEP_AND_COPY)
    namespace: dict = {}
    code = compile(source, inline_closurecall.__file__, "exec")
    exec(code, vars(inline_closurecall), namespace)  # numba's own module globals, so its helpers resolve
    inline_closurecall.InlineWorker.inline_ir = namespace["inline_ir"]  # type: ignore[method-assign]
    INSTALLED = True
    return True


install()
