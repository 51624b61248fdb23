"""The occupancy grid: shape, resolution and origin, and world <-> cell conversion.

A grid discretises the world into ``K`` binary cells ``m_1..m_K`` (Section 2.1). Cells are indexed
row-major: a 2D grid of shape ``(rows, cols)`` stores cell ``(row, col)`` at flat index
``row * cols + col``; ``x`` runs along columns and ``y`` along rows. A 1D grid has shape ``(K,)`` and is
treated as one row (``y`` is ignored when a 1D grid converts coordinates).

Cell ``(row, col)`` covers the world square
``[ox + col * res, ox + (col + 1) * res) x [oy + row * res, oy + (row + 1) * res)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Grid", "MAX_CELLS"]

#: Default limit on the cells of a grid the command line and the experiments build from a file or a spec: a
#: larger grid is refused with this limit in the message (``--max-cells``, ``[experiment] max_cells``), before a
#: float64 map of it (8 bytes a cell, several at once) takes the machine's memory.
MAX_CELLS = 50_000_000


def _cell_count(value: object, i: int, shape: object) -> int:
    """``shape[i]`` as an int, refusing non-integral values (``20.5``) and non-numbers instead of truncating."""
    if isinstance(value, bool | np.bool_) or not isinstance(value, int | float | np.integer | np.floating):
        raise TypeError(f"Grid.shape[{i}] must be an integer, got {value!r} in {shape!r}")
    if not np.isfinite(value) or float(value) != int(value):
        raise ValueError(f"Grid.shape[{i}] must be a whole number of cells, got {value!r} in {shape!r}")
    return int(value)


@dataclass(frozen=True)
class Grid:
    """A regular 1D or 2D grid.

    Args:
        shape: ``(K,)`` for a 1D grid or ``(rows, cols)`` for a 2D grid.
        resolution: metres per cell (> 0).
        origin: world coordinates of the corner of cell 0 (``(x,)`` or ``(x, y)``; 1D accepts a float).

    >>> g = Grid((4, 5), resolution=0.5, origin=(-1.0, 0.0))
    >>> g.num_cells
    20
    >>> g.world_to_cell([[0.2, 1.2]]).tolist()
    [[2, 2]]
    """

    shape: tuple[int, ...]
    resolution: float = 1.0
    origin: tuple[float, float] = (0.0, 0.0)

    def __post_init__(self) -> None:
        raw = np.atleast_1d(np.asarray(self.shape, dtype=object))
        if raw.ndim != 1 or len(raw) not in (1, 2):
            raise ValueError(f"Grid.shape must have 1 or 2 entries, got {self.shape!r}")
        shape = tuple(_cell_count(s, i, self.shape) for i, s in enumerate(raw))
        for i, s in enumerate(shape):
            if s <= 0:
                raise ValueError(f"Grid.shape[{i}] must be positive, got {s}")
        res = float(self.resolution)
        if not np.isfinite(res) or res <= 0:
            raise ValueError(f"Grid.resolution must be a positive finite number, got {self.resolution!r}")
        origin = np.atleast_1d(np.asarray(self.origin, dtype=float))
        if origin.size == 1:
            origin = np.array([origin[0], 0.0])
        if origin.shape != (2,) or not np.all(np.isfinite(origin)):
            raise ValueError(f"Grid.origin must be (x, y) finite numbers, got {self.origin!r}")
        object.__setattr__(self, "shape", shape)
        object.__setattr__(self, "resolution", res)
        object.__setattr__(self, "origin", (float(origin[0]), float(origin[1])))

    # ------------------------------------------------------------------ shape
    @property
    def ndim(self) -> int:
        """1 or 2."""
        return len(self.shape)

    @property
    def num_cells(self) -> int:
        """K, the number of cells."""
        return int(np.prod(self.shape))

    @property
    def rows(self) -> int:
        """Rows of the grid seen as 2D (1 for a 1D grid)."""
        return 1 if self.ndim == 1 else self.shape[0]

    @property
    def cols(self) -> int:
        """Columns of the grid seen as 2D (K for a 1D grid)."""
        return self.shape[-1]

    @property
    def extent(self) -> tuple[float, float, float, float]:
        """``(xmin, xmax, ymin, ymax)`` in metres, as matplotlib's ``imshow(extent=...)`` wants it."""
        ox, oy = self.origin
        return (ox, ox + self.cols * self.resolution, oy, oy + self.rows * self.resolution)

    # ------------------------------------------------------------ conversions
    def world_to_continuous(self, xy: np.ndarray) -> np.ndarray:
        """World ``(x, y)`` in metres -> continuous cell coordinates ``(u, v)`` = (column, row) units.

        ``xy``: ``N x 2`` (or ``N`` / ``N x 1`` for 1D grids, y taken as the middle of the row).
        """
        xy = self._as_xy(xy)
        ox, oy = self.origin
        uv = np.empty_like(xy)
        uv[:, 0] = (xy[:, 0] - ox) / self.resolution
        uv[:, 1] = (xy[:, 1] - oy) / self.resolution if self.ndim == 2 else 0.5
        return uv

    def world_to_cell(self, xy: np.ndarray) -> np.ndarray:
        """World coordinates -> integer ``(row, col)`` (``N x 2``; ``N`` for 1D grids). No bounds check."""
        uv = np.floor(self.world_to_continuous(xy)).astype(np.int64)
        if self.ndim == 1:
            return uv[:, 0]
        return np.stack([uv[:, 1], uv[:, 0]], axis=1)

    def cell_to_world(self, cells: np.ndarray) -> np.ndarray:
        """Cell ``(row, col)`` (or 1D index) -> world coordinates of the cell centre (``N x 2``)."""
        cells = np.asarray(cells)
        ox, oy = self.origin
        if self.ndim == 1:
            col = np.atleast_1d(cells).astype(float)
            row = np.zeros_like(col)
        else:
            cells = np.atleast_2d(cells).astype(float)
            row, col = cells[:, 0], cells[:, 1]
        return np.stack([ox + (col + 0.5) * self.resolution, oy + (row + 0.5) * self.resolution], 1)

    def flat_index(self, cells: np.ndarray) -> np.ndarray:
        """``(row, col)`` -> flat row-major index (identity for 1D). A cell off the grid (as
        :meth:`world_to_cell` gives for a point outside it) is refused (``ValueError``): its row-major index
        would name another cell, or none."""
        cells = np.asarray(cells, dtype=np.int64)
        if self.ndim == 1:
            off = (cells < 0) | (cells >= self.num_cells)
            if off.any():
                raise ValueError(f"cell {int(cells[off].ravel()[0])} lies off the grid (cells 0..{self.num_cells - 1})")
            return cells
        if cells.shape[-1:] != (2,):
            raise ValueError(f"cells must be (..., 2) (row, col) pairs, got shape {cells.shape}")
        r, c = cells[..., 0], cells[..., 1]
        off = (r < 0) | (r >= self.rows) | (c < 0) | (c >= self.cols)
        if off.any():
            i = np.argwhere(off)[0]
            bad = cells[tuple(i)] if cells.ndim > 1 else cells
            raise ValueError(f"cell (row {int(bad[0])}, col {int(bad[1])}) lies off the {self.rows} x {self.cols} grid")
        return r * self.cols + c

    def contains(self, xy: np.ndarray) -> np.ndarray:
        """Whether world points lie inside the grid (boolean ``N``)."""
        uv = self.world_to_continuous(xy)
        inside = (uv[:, 0] >= 0) & (uv[:, 0] < self.cols)
        if self.ndim == 2:
            inside &= (uv[:, 1] >= 0) & (uv[:, 1] < self.rows)
        return inside

    def _as_xy(self, xy: np.ndarray) -> np.ndarray:
        xy = np.asarray(xy, dtype=float)
        if xy.ndim == 0:
            xy = xy.reshape(1, 1)
        if xy.ndim == 1:
            xy = xy[:, None] if self.ndim == 1 else xy[None, :]
        if xy.shape[1] == 1:
            xy = np.concatenate([xy, np.full_like(xy, self.origin[1])], axis=1)
        return xy

    @classmethod
    def line(cls, num_cells: int, resolution: float = 1.0) -> Grid:
        """The 1D grid of the thesis's toy problems: cells ``0..K-1`` starting at ``x = 0``."""
        return cls((num_cells,), resolution=resolution, origin=(0.0, 0.0))
