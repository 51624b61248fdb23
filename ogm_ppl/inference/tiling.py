r"""Patch geometry shared by every patch method: shapes (Fig. 3.1), where a patch's cells lie, and tilings.

A patch is a set of ``(row, col)`` offsets; placed at an anchor it covers the cells ``anchor + offset``
that are on the grid and latent (``-1`` elsewhere, the rule of the compiled ``build_patch``). Patch maps
(Chapter 3), patch Gibbs (Algorithm 2) and patch guides all tile the grid with the functions here.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from ogm_ppl.models.occupancy import OccupancyModel

__all__ = ["patch_shape", "patch_cells", "tiling_starts", "tile_patches", "centred_patches"]


def tiling_starts(offset: int, size: int, n: int) -> np.ndarray:
    """Start positions of a tiling of ``0..n-1`` by runs of ``size`` in which a run starts at ``offset``
    (a partial run may start before 0)."""
    start = int(offset) % size
    return np.arange(start - size if start else 0, n, size)


def patch_cells(model: OccupancyModel, anchors: np.ndarray, dr: np.ndarray, dc: np.ndarray) -> np.ndarray:
    """Cells of the patch ``(dr, dc)`` placed at each ``(row, col)`` anchor (``n x 2``), vectorised:
    ``n x L`` with ``-1`` where a cell is off the grid or pinned (the rule of the compiled ``build_patch``)."""
    g = model.grid
    anchors = np.asarray(anchors, dtype=np.int64).reshape(-1, 2)
    r = anchors[:, :1] + dr[None, :]
    c = anchors[:, 1:] + dc[None, :]
    inside = (r >= 0) & (r < g.rows) & (c >= 0) & (c < g.cols)
    k = np.where(inside, r * g.cols + c, 0)
    ok = inside & ~model.known_free.numpy()[k]
    return np.where(ok, k, -1)


def patch_shape(
    shape: int | str | tuple[int, int] | np.ndarray, ndim: int, max_cells: int = 20
) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]]:
    """Row and column offsets of a patch shape (Fig. 3.1).

    ``shape``: an int ``L`` (1D: a run of ``L`` cells; 2D: an ``L``-cell horizontal run), ``(h, w)`` (a
    rectangle, e.g. ``(3, 3)``), ``"plus"`` (the 4-neighbourhood, L = 5), ``"square"`` (3 x 3, the
    8-neighbourhood, L = 9), or an ``L x 2`` array of offsets. More than ``max_cells`` cells are refused
    (``2^L`` configurations).
    """
    off: np.ndarray
    if isinstance(shape, str):
        if shape == "plus":
            pairs = [(0, 0), (-1, 0), (1, 0), (0, -1), (0, 1)]
        elif shape == "square":
            pairs = [(r, c) for r in (-1, 0, 1) for c in (-1, 0, 1)]
        else:
            raise ValueError(f"unknown patch shape {shape!r}; use an int, (h, w), 'plus' or 'square'")
        off = np.array(pairs)
    elif isinstance(shape, (int, np.integer)):
        L = int(shape)
        if L < 1:
            raise ValueError(f"patch length must be >= 1, got {shape}")
        off = np.stack([np.zeros(L, int), np.arange(L)], 1)
    else:
        arr = np.asarray(shape)
        if arr.shape == (2,) and np.issubdtype(arr.dtype, np.integer):
            h, w = int(arr[0]), int(arr[1])
            if h < 1 or w < 1:
                raise ValueError(f"patch (h, w) must be positive, got {shape!r}")
            off = np.array([(r, c) for r in range(h) for c in range(w)])
        elif arr.ndim == 2 and arr.shape[1] == 2:
            off = arr.astype(int)
        else:
            raise ValueError(f"cannot read patch shape {shape!r}")
    if ndim == 1 and np.any(off[:, 0] != 0):
        raise ValueError("a 1D grid only takes patches along the row")
    if len(off) > max_cells:
        raise ValueError(
            f"patches of {len(off)} cells mean 2^{len(off)} configurations; at most {max_cells} "
            "(more only for a table prior whose tiles are the patches)"
        )
    return np.ascontiguousarray(off[:, 0], dtype=np.int64), np.ascontiguousarray(off[:, 1], dtype=np.int64)


def _anchors(rows, cols) -> np.ndarray:
    R, C = np.meshgrid(np.asarray(rows), np.asarray(cols), indexing="ij")
    return np.stack([R.ravel(), C.ravel()], 1)


def tile_patches(model: OccupancyModel, patch=3, offset=0) -> np.ndarray:
    """Non-overlapping patches covering the grid, ``P x L`` cells with ``-1`` where cut off or pinned.

    Runs and rectangles tile with a patch starting at column ``offset`` (or ``(row, col)``); the
    plus-shaped 4-neighbourhood (``"plus"``, L = 5) tiles the plane with centres where
    ``(col + 2 row - offset) mod 5 == 0``.
    """
    g = model.grid
    if isinstance(patch, str) and patch == "plus":
        dr, dc = patch_shape("plus", g.ndim)
        anchors = _anchors(range(-1, g.rows + 1), range(-2, g.cols + 2))
        anchors = anchors[(anchors[:, 1] + 2 * anchors[:, 0] - int(offset)) % 5 == 0]
        arr = patch_cells(model, anchors, dr, dc)
        return arr[(arr >= 0).any(1)]
    dr, dc = patch_shape(patch, g.ndim)
    if dr.min() != 0 or dc.min() != 0 or len(dr) != (dr.max() + 1) * (dc.max() + 1):
        raise ValueError("non-overlapping patches must be runs, rectangles or 'plus'")
    h, w = int(dr.max()) + 1, int(dc.max()) + 1
    orow, ocol = (0, int(offset)) if isinstance(offset, (int, np.integer)) else (int(o) for o in offset)
    arr = patch_cells(model, _anchors(tiling_starts(orow, h, g.rows), tiling_starts(ocol, w, g.cols)), dr, dc)
    return arr[(arr >= 0).any(1)]


def centred_patches(model: OccupancyModel, patch=3) -> tuple[np.ndarray, int]:
    """A patch centred on every latent cell (for the overlapping offline map) and the centre's column."""
    dr, dc = patch_shape(patch, model.grid.ndim)
    if isinstance(patch, str):
        cr, cc = 0, 0
    else:
        cr, cc = int(dr.max()) // 2, int(dc.max()) // 2
    dr, dc = dr - cr, dc - cc
    centre = int(np.flatnonzero((dr == 0) & (dc == 0))[0])
    anchors = np.stack(np.divmod(model.latent.numpy(), model.grid.cols), 1)
    return patch_cells(model, anchors, dr, dc), centre
