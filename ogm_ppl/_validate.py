"""Shared checks of user input: binary maps and numeric options, refused with the argument's name.

A map is a vector ``m in {0, 1}^K`` (Section 2.1); every entry point that takes one (``log_joint``, the MAP
start ``init``, the patch maps' ``reference``) checks it here, so ``0.5`` or ``NaN`` is never read as
"occupied" by a ``!= 0`` test downstream.

>>> as_binary_maps([0, 1, 1], 3, "init").tolist()
[0.0, 1.0, 1.0]
>>> as_binary_maps([0, 0.5, 1], 3, "init")
Traceback (most recent call last):
...
ValueError: init must hold only 0 and 1, found 0.5
>>> finite_number(-5, "max_usable_range", minimum=0.0, strict=True)
Traceback (most recent call last):
...
ValueError: max_usable_range must be a finite number > 0.0, got -5
"""

from __future__ import annotations

import math
import numbers

import numpy as np
import torch

__all__ = ["as_binary_maps", "check_binary", "finite_number"]


def check_binary(maps: torch.Tensor, what: str) -> None:
    """Raise ``ValueError`` naming ``what`` unless every entry of ``maps`` is exactly 0 or 1 (no NaN/inf)."""
    if maps.is_floating_point() and not torch.isfinite(maps).all():
        raise ValueError(f"{what} holds NaN or infinite values")
    bad = (maps != 0) & (maps != 1)
    if bad.any():
        raise ValueError(f"{what} must hold only 0 and 1, found {maps[bad].flatten()[0].item()!r}")


def as_binary_maps(value: object, num_cells: int | None, what: str, flatten: bool = False) -> torch.Tensor:
    """``value`` (tensor, array or nested list) as float64 maps ``... x K`` of 0/1 entries.

    Args:
        value: the maps; strings, ``None`` and object arrays are refused with ``TypeError``.
        num_cells: ``K``, required size of the last dimension (``None``: any).
        what: the argument's name, used in every message.
        flatten: read ``value`` as one map of ``K`` entries in any shape (a ``rows x cols`` image).
    """
    if isinstance(value, str | bytes) or value is None:
        raise TypeError(f"{what} must be a 0/1 array (tensor, numpy array or list), got {type(value).__name__}")
    if isinstance(value, torch.Tensor):
        t = value.detach().cpu()
    else:
        arr = np.asarray(value)
        if arr.dtype.kind not in "biuf":
            raise TypeError(f"{what} must be a numeric 0/1 array, got dtype {arr.dtype} ({type(value).__name__})")
        t = torch.from_numpy(np.ascontiguousarray(arr))
    if t.is_complex():
        raise TypeError(f"{what} must be a real 0/1 array, got dtype {t.dtype}")
    if flatten:
        t = t.reshape(-1)
    if num_cells is not None and (t.dim() == 0 or t.shape[-1] != num_cells):
        raise ValueError(
            f"{what} must have {num_cells} cells in the last dimension (the grid's), got shape {tuple(t.shape)}"
        )
    check_binary(t, what)
    return t.to(torch.float64)


def finite_number(
    value: object, name: str, minimum: float | None = None, strict: bool = False, maximum: float | None = None
) -> float:
    """``value`` as a float, refusing non-numbers, NaN, infinities and values below ``minimum`` (or equal to
    it with ``strict``) or above ``maximum``, with ``name`` in the message."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise TypeError(f"{name} must be a number, got {value!r} ({type(value).__name__})")
    v = float(value)
    bound = "" if minimum is None else f" {'>' if strict else '>='} {minimum}"
    if maximum is not None:
        bound += f" and <= {maximum}"
    ok = math.isfinite(v)
    if ok and minimum is not None:
        ok = v > minimum if strict else v >= minimum
    if ok and maximum is not None:
        ok = v <= maximum
    if not ok:
        raise ValueError(f"{name} must be a finite number{bound}, got {value!r}")
    return v
