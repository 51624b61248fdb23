"""Modules of one's own that register kinds: map methods, prior kinds, sensor kinds.

A researcher's module registers its kinds on import (``register_method``, ``register_prior``,
``register_sensor``). Every process finds it when it is named in ``$OGM_PPL_METHODS`` (comma-separated module
names) or is an entry point of the group ``ogm_ppl.methods`` in a package's metadata: :func:`load_extensions`
imports them, once per process, and again after a failed import. The registries call it on a lookup of a kind
they do not hold yet, and the method registry before every lookup, so a script, a notebook, the command line and
dask workers find the same kinds.

This module imports nothing of the library: every registry, at any layer, may use it.
"""

from __future__ import annotations

import functools
import importlib
import os
from collections.abc import Callable

__all__ = ["ENTRY_POINT_GROUP", "ENV_VAR", "MethodModuleError", "load_extensions"]

#: environment variable naming extra modules (comma-separated) that register methods, priors or sensors
ENV_VAR = "OGM_PPL_METHODS"
#: entry-point group of packages that register methods, priors or sensors
ENTRY_POINT_GROUP = "ogm_ppl.methods"

_loaded = False


class MethodModuleError(ImportError):
    """A module named in ``$OGM_PPL_METHODS``, or an entry point of the group ``ogm_ppl.methods``, that cannot be
    imported, or that calls ``sys.exit`` on import (the message names it and what it did)."""


def load_extensions() -> None:
    """Import the modules of ``$OGM_PPL_METHODS`` and the entry points of the group ``ogm_ppl.methods`` (once per
    process; again after a failed import). :class:`MethodModuleError` names a module that cannot be imported or
    that calls ``sys.exit`` on import (the exit is not let through: the caller's process goes on)."""
    global _loaded
    if _loaded:
        return
    _loaded = True  # before the imports: their register calls may look kinds up and come back here
    from importlib.metadata import entry_points

    where: list[tuple[Callable[[], object], str]] = [
        (functools.partial(importlib.import_module, mod), f"${ENV_VAR} names the module {mod!r}")
        for mod in filter(None, (s.strip() for s in os.environ.get(ENV_VAR, "").split(",")))
    ]
    where += [
        (ep.load, f"the entry point {ep.name!r} of the group {ENTRY_POINT_GROUP!r} ({ep.value})")
        for ep in entry_points(group=ENTRY_POINT_GROUP)
    ]
    for load, said in where:
        try:
            load()
        except SystemExit as e:  # sys.exit() at import: a library call must not end the caller's process
            _loaded = False
            raise MethodModuleError(f"{said}, which called sys.exit({e.code!r}) on import") from e
        except Exception as e:
            _loaded = False  # no half-filled registry: the next call tries again and says why again
            raise MethodModuleError(f"{said}, which cannot be imported: {type(e).__name__}: {e}") from e
