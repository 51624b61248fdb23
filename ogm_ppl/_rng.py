"""The global random streams a seeded library call leaves as it found them.

A function that takes a ``seed`` (:func:`~ogm_ppl.inference.run_gibbs`,
:func:`~ogm_ppl.inference.variational.fit_guide`, ...)
seeds the global generators to be reproducible; without care that also resets the caller's streams, so that
``pyro.set_rng_seed(1)`` then replicates of ``fit_guide(...); MCMC(...).run()`` come out identical. Such functions
run under :func:`keeps_global_rng`: torch's CPU generator, NumPy's global generator and Python's ``random`` are
saved on entry and restored on exit (also on an exception or Ctrl-C).
"""

from __future__ import annotations

import contextlib
import functools
import random
from collections.abc import Callable, Iterator
from typing import ParamSpec, TypeVar

import numpy as np
import torch

__all__ = ["keeps_global_rng", "preserved_rng"]

P = ParamSpec("P")
R = TypeVar("R")


@contextlib.contextmanager
def preserved_rng() -> Iterator[None]:
    """Save torch's CPU generator, NumPy's global generator and Python's ``random`` state; restore them on exit."""
    t, n, r = torch.get_rng_state(), np.random.get_state(), random.getstate()
    try:
        yield
    finally:
        torch.set_rng_state(t)
        np.random.set_state(n)
        random.setstate(r)


def keeps_global_rng(fn: Callable[P, R]) -> Callable[P, R]:
    """Decorator: ``fn`` runs under :func:`preserved_rng`."""

    @functools.wraps(fn)
    def wrapper(*args: P.args, **kwargs: P.kwargs) -> R:
        with preserved_rng():
            return fn(*args, **kwargs)

    return wrapper
