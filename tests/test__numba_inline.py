"""Numba's inliner with one deep-copy memo per callee (:mod:`ogm_ppl._numba_inline`): installed under the pinned
numba, and the code it compiles is numba's own, instruction for instruction."""

from __future__ import annotations

import re

import numba as nb
import numpy as np
from numba.core import inline_closurecall

from ogm_ppl import _numba_inline


def _nested():
    """A fresh dispatcher (so each call compiles) that inlines a helper which inlines another, with loops and
    branches (many blocks, a scope with many variables: what the copy is about)."""

    @nb.njit(inline="always")
    def inner(a, i):
        s = 0.0
        for j in range(i):
            if a[j] > 0:
                s += a[j]
            else:
                s -= 1.0
        return s

    @nb.njit(inline="always")
    def middle(a, i):
        t = inner(a, i)
        if t > 1.0:
            t += inner(a, i - 1)
        return t

    @nb.njit
    def outer(a):
        acc = 0.0
        for i in range(a.shape[0]):
            acc += middle(a, i)
        return acc

    return outer


def _canonical(llvm: str) -> str:
    """The LLVM IR without comments and with the numbers in names dropped (block labels and a dispatcher's unique
    id count up over a process, so two compiles of one function differ only there)."""
    return re.sub(r"(?<=[A-Za-z_.$])\d+", "#", re.sub(r"\s*;.*$", "", llvm, flags=re.M))


X = np.linspace(-1.0, 2.0, 7)


def _compile(inline_ir) -> tuple[float, str]:
    patched = inline_closurecall.InlineWorker.inline_ir
    inline_closurecall.InlineWorker.inline_ir = inline_ir
    try:
        f = _nested()
        return f(X), f.inspect_llvm(f.signatures[0])
    finally:
        inline_closurecall.InlineWorker.inline_ir = patched


def test_installed_under_the_pinned_numba():
    assert _numba_inline.INSTALLED, f"numba {nb.__version__}: InlineWorker.inline_ir's source changed"
    assert inline_closurecall.InlineWorker.inline_ir is not _numba_inline.ORIGINAL_INLINE_IR


def test_compiles_the_same_code_as_numbas_own_inliner():
    ours, ours_llvm = _compile(inline_closurecall.InlineWorker.inline_ir)
    theirs, theirs_llvm = _compile(_numba_inline.ORIGINAL_INLINE_IR)
    assert ours == theirs == _nested().py_func(X)  # exact: sums of a few multiples of 0.5
    assert "inner" in ours_llvm  # the inlined helpers' variables are there: they were inlined
    assert _canonical(ours_llvm) == _canonical(theirs_llvm)


def test_the_environment_can_keep_numbas_own_inliner():
    """``OGM_PPL_NUMBA_INLINE_PATCH=0``: a fresh process that imports the library leaves numba's method in place."""
    import os
    import subprocess
    import sys

    code = (
        "import ogm_ppl, ogm_ppl._numba_inline as p; from numba.core import inline_closurecall as ic; "
        "print(p.INSTALLED, ic.InlineWorker.inline_ir is p.ORIGINAL_INLINE_IR)"
    )
    env = {**os.environ, "OGM_PPL_NUMBA_INLINE_PATCH": "0"}
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True).stdout
    assert out.split() == ["False", "True"]
