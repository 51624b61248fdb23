"""Scratch of the patch weights of correlated priors, allocated once per sweep (no allocation per update)."""

from __future__ import annotations

from typing import NamedTuple

import numba as nb
import numpy as np

__all__ = ["MEMO_BITS", "TileScratch", "tile_scratch", "tile_scratch_on"]

#: a touched tile's factor is memoised per sub-configuration when it shares at most this many patch cells
MEMO_BITS = 10


class TileScratch(NamedTuple):
    """Scratch of :func:`~ogm_ppl.priors.compiled.tiles.tile_patch_setup` /
    :func:`~ogm_ppl.priors.compiled.tiles.tile_patch_factors`, made by :func:`tile_scratch` (``C``: the
    kind's :func:`~ogm_ppl.priors.compiled.registry.scratch_capacity`)."""

    bit_of: np.ndarray  # K int64, all -1 between updates: the patch bit of a cell
    touch: np.ndarray  # C int64: touched tiles
    base: np.ndarray  # C int64: their window keys with the patch cells read as free
    seg: np.ndarray  # C int64: their segments
    pr_off: np.ndarray  # C + 1 int64: pairs of tile q are pr_off[q]:pr_off[q + 1]
    pr_pb: np.ndarray  # C int64: patch bit of a pair
    pr_wb: np.ndarray  # C int64: window bit of a pair
    memo_off: np.ndarray  # C + 1 int64: start of tile q's memo (-1: not memoised); memo_off[nt] = size
    memo: np.ndarray  # C << MEMO_BITS float64: factor per sub-configuration (nan: not yet computed)


@nb.njit(cache=True)
def tile_scratch(num_cells, C):
    """A :class:`TileScratch` for a ``num_cells``-cell map and up to ``C`` touched tiles (and pairs)."""
    return tile_scratch_on(np.full(num_cells, -1, np.int64), C)


@nb.njit(cache=True)
def tile_scratch_on(bit_of, C):
    """A :class:`TileScratch` over the given cell -> patch bit map ``bit_of`` (``K`` int64, all -1; shared by
    updates of disjoint patches, e.g. the tiles of a chromatic sweep) with scratch of its own for up to ``C``
    touched tiles (and pairs)."""
    C = max(C, 1)
    return TileScratch(
        bit_of,
        np.empty(C, np.int64),
        np.empty(C, np.int64),
        np.empty(C, np.int64),
        np.empty(C + 1, np.int64),
        np.empty(C, np.int64),
        np.empty(C, np.int64),
        np.empty(C + 1, np.int64),
        np.empty(C << MEMO_BITS, np.float64),
    )
