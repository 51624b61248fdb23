"""torch's numeric settings for a block of work: the default dtype (float64 for exact inference and the fits that
compare with it) and the thread count (float32 sums, a guide's convolutions, depend on it).

>>> import torch
>>> before = torch.get_default_dtype()
>>> with float64():
...     torch.zeros(1).dtype
torch.float64
>>> torch.get_default_dtype() == before
True
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator

import torch

__all__ = ["float64", "torch_threads"]


@contextlib.contextmanager
def float64() -> Iterator[None]:
    """torch's default dtype float64 inside, the caller's restored after (also when the block raises)."""
    old = torch.get_default_dtype()
    torch.set_default_dtype(torch.float64)
    try:
        yield
    finally:
        torch.set_default_dtype(old)


@contextlib.contextmanager
def torch_threads(n: int) -> Iterator[None]:
    """torch on ``n`` threads inside (a float32 sum's order, hence its rounding, depends on the count), the
    caller's count restored after (also when the block raises)."""
    before = torch.get_num_threads()
    torch.set_num_threads(n)
    try:
        yield
    finally:
        torch.set_num_threads(before)
