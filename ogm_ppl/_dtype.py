"""torch's default dtype for a block of work: float64 for exact inference and the fits that compare with it.

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

__all__ = ["float64"]


@contextlib.contextmanager
def float64() -> Iterator[None]:
    """torch's default dtype float64 inside, the caller's restored after (also when the block raises)."""
    old = torch.get_default_dtype()
    torch.set_default_dtype(torch.float64)
    try:
        yield
    finally:
        torch.set_default_dtype(old)
