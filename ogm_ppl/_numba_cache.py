"""Numba's disk cache for the compiled functions that take a kind's bundle, kept to the library's own types.

Numba keeps one cache index per compiled function and pickles the type of every specialisation in it. A bundle
class of one's own (a compiled prior or reading kind of a notebook, a script or a test module) in that index makes
every process that cannot import its module fail to load the function at all, for the library's own kinds too
(``ModuleNotFoundError: No module named 'tests'``). A second, uncached dispatcher at a kernel's entry point does not
keep it out: a compiled function that the kernel calls with the bundle (not inlined) compiles through its own
dispatcher, with its own index.

:func:`njit_shipped` compiles like ``numba.njit(cache=True)``, but keeps on disk only the specialisations whose
types name nothing beyond the library, numba, numpy, llvmlite and the standard library
(:func:`cacheable_signature`): the shipped kinds compile once and load from disk; a kind of one's own compiles once
per process, in every function of the call tree that takes it. Numba has no public hook for this: the dispatcher's
cache (a :class:`numba.core.caching.FunctionCache`) is replaced by :class:`ShippedTypesCache`, which filters the
signatures and otherwise caches as numba does.
"""

from __future__ import annotations

import io
import pickle
import sys
import types
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numba as nb
from numba.core.caching import FunctionCache

__all__ = ["ShippedTypesCache", "cache_index", "cacheable_signature", "njit_shipped"]

#: the top-level packages whose classes a cache index may name (besides the standard library's)
SHIPPED_ROOTS = frozenset({"ogm_ppl", "numba", "numpy", "llvmlite"})


def _everywhere(module: str | None) -> bool:
    """Whether every process that imports the library can import ``module``."""
    root = (module or "__main__").partition(".")[0]
    return root in SHIPPED_ROOTS or (root != "__main__" and root in sys.stdlib_module_names)


class _Names(pickle.Pickler):
    """Pickles into a scratch buffer, recording the modules of the classes and functions the object names (what
    unpickling it has to import)."""

    def __init__(self) -> None:
        super().__init__(io.BytesIO(), protocol=pickle.HIGHEST_PROTOCOL)
        self.modules: set[str | None] = set()

    def persistent_id(self, obj: Any) -> None:
        if isinstance(obj, type | types.FunctionType | types.BuiltinFunctionType):
            self.modules.add(getattr(obj, "__module__", None))
        return None


def cacheable_signature(sig) -> bool:
    """Whether a specialisation of numba types ``sig`` may go into a disk cache index: every class and function it
    names comes from the library, numba, numpy, llvmlite or the standard library. A type that does not pickle (a
    class defined inside a function) is not cacheable."""
    names = _Names()
    try:
        names.dump(sig)
    except (pickle.PicklingError, AttributeError, TypeError):
        return False
    return all(_everywhere(m) for m in names.modules)


class ShippedTypesCache(FunctionCache):
    """Numba's per-function disk cache, passing over the specialisations that :func:`cacheable_signature` refuses
    (they compile in each process and stay out of the index)."""

    def load_overload(self, sig, target_context):
        return super().load_overload(sig, target_context) if cacheable_signature(sig) else None

    def save_overload(self, sig, data) -> None:
        if cacheable_signature(sig):
            super().save_overload(sig, data)

    @property
    def index_path(self) -> Path:
        """The function's index file, which names the type of every specialisation on disk."""
        return Path(self._cache_file._index_path)


def njit_shipped(fn: Callable | None = None, **options):
    """``numba.njit(cache=True, **options)`` with the disk cache kept to the shipped types (module docstring); as
    ``@njit_shipped`` or ``@njit_shipped(option=...)``."""
    if "cache" in options:
        raise TypeError("njit_shipped always caches (the shipped types only): leave out cache=")

    def wrap(f: Callable):
        dispatcher = nb.njit(**options)(f)
        dispatcher._cache = ShippedTypesCache(dispatcher.py_func)  # numba's own cache, filtered
        return dispatcher

    return wrap if fn is None else wrap(fn)


def cache_index(dispatcher) -> bytes:
    """The bytes of the disk cache index of a function of :func:`njit_shipped` (``b""`` before any is written)."""
    path = dispatcher._cache.index_path
    return path.read_bytes() if path.exists() else b""
