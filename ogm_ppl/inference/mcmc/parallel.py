"""Single-cell Gibbs sweeps on every core of one machine, exactly: chromatic tile sweeps (Section 4.1).

:class:`ChromaticCellGibbs` is :class:`~ogm_ppl.inference.mcmc.gibbs.CellGibbs` (heat bath or metropolised,
systematic / permutation / random scan, ``region=``) with the sweep reordered so that it runs in threads:
the grid is cut into ``tile x tile`` tiles coloured as a 2 x 2 checkerboard; the four colour phases run in
turn, and within a phase every tile of the colour is swept (its own scan over its cells) by numba's threads
at once; cells on rays that reach two tiles of one colour (*long* cells) are updated last, one after another. Tiles at
least as large as every factor (ray, prior window) make the updates of a phase commute exactly, so the
sweep is a composition of single-cell Gibbs updates and leaves the posterior invariant; the proof, the
handling of the kept likelihood sums that several threads write, and the random streams are in
:mod:`ogm_ppl.inference._kernels.parallel`. The chain is a function of the seed drawn from torch's
generator each sweep, identical for every thread count.

:class:`ChromaticPatchGibbs` does the same for :class:`~ogm_ppl.inference.mcmc.gibbs.PatchGibbs` (Algorithms 1
and 2, every prior kind with a compiled face, backed-off tables' escape move included): tiles whose side is a
multiple of the patch's height and width, aligned with the patch tiling, so that every patch lies in one tile;
patches on a ray that reaches two tiles of one colour, or straddling tiles (non-rectangular shapes), are
updated last (:mod:`ogm_ppl.inference._kernels.parallel_patch`).

Choosing ``tile``: the default, the longest ray's extent (and at least the prior's), makes every cell short;
on maps much larger than the sensor's range that leaves many tiles per colour. Smaller tiles give more
tiles per phase but move the cells on longer rays into the serial long phase (:attr:`layout` reports how
many), the trade-off ``benchmarks/bench_parallel.py`` measures.
"""

from __future__ import annotations

import numba
import numpy as np
import torch

from ogm_ppl.inference._kernels import cell_sweep as cs
from ogm_ppl.inference._kernels import parallel as par
from ogm_ppl.inference._kernels import parallel_patch as pp
from ogm_ppl.inference.mcmc.gibbs import _SCAN_CODES, CellGibbs, PatchGibbs
from ogm_ppl.inference.tiling import patch_cells
from ogm_ppl.models.occupancy import OccupancyModel
from ogm_ppl.priors.compiled import kind_of

__all__ = ["ChromaticCellGibbs", "ChromaticPatchGibbs", "max_threads"]


def max_threads() -> int:
    """The most threads numba can run (``NUMBA_NUM_THREADS``, fixed when numba starts)."""
    return int(numba.config.NUMBA_NUM_THREADS)  # type: ignore[attr-defined]


class _Threaded:
    """The ``threads`` setting of the chromatic kernels: how many of numba's threads a sweep uses."""

    _threads: int | None = None

    @property
    def threads(self) -> int:
        """The numba threads a sweep uses."""
        return numba.get_num_threads() if self._threads is None else self._threads

    @threads.setter
    def threads(self, n: int | None) -> None:
        most = max_threads()
        if n is not None and not 1 <= int(n) <= most:
            raise ValueError(f"threads must lie in 1..{most}, got {n}")
        self._threads = None if n is None else int(n)


class ChromaticCellGibbs(_Threaded, CellGibbs):
    """Single-cell Gibbs in chromatic tile sweeps (module docstring), on ``threads`` of numba's threads.

    Args:
        model, scan, update, init, delta, region: as :class:`~ogm_ppl.inference.mcmc.gibbs.CellGibbs`
            (priors with a compiled face only). ``scan`` orders the cells *within* each tile and within the
            long cells; tiles and phases keep their order.
        tile: the tile side in cells (``None``: the longest ray's extent, at least the prior's factor
            extent, at least 1). Must be at least the prior's factor extent
            (:func:`~ogm_ppl.inference._kernels.parallel.prior_extent`).
        threads: numba threads for the sweeps (``None``: numba's current number); at most
            ``numba.config.NUMBA_NUM_THREADS``. The chain does not depend on it.
    """

    def __init__(
        self,
        model: OccupancyModel,
        scan: str = "systematic",
        update: str = "gibbs",
        init="ogm",
        delta="haehnel",
        region=None,
        tile: int | None = None,
        threads: int | None = None,
    ) -> None:
        super().__init__(model, scan, update, init, delta, region)
        if tile is not None and int(tile) < 1:
            raise ValueError(f"tile must be a positive number of cells, got {tile}")
        self.tile = None if tile is None else int(tile)
        self.threads = threads

    def _set_up(self) -> None:
        super()._set_up()
        if self._compiled is None:
            raise ValueError("ChromaticCellGibbs needs a prior with a compiled face (prior.compiled())")
        g = self.model.grid
        self.prior_extent = par.prior_extent(self._compiled)
        ext = par.ray_extents(self._offsets, self._cells, g.cols)
        self.ray_extent = int(ext.max(initial=0))
        T = max(self.ray_extent, self.prior_extent, 1) if self.tile is None else self.tile
        if T < self.prior_extent:
            raise ValueError(f"tile {T} is smaller than the prior's factor extent {self.prior_extent}")
        self._layout = par.tile_layout(self._visit, self._offsets, self._cells, self._c_off, g.rows, g.cols, T)

    @property
    def layout(self) -> par.TileLayout:
        """The tiles, their colours and the long cells (:class:`~ogm_ppl.inference._kernels.parallel.TileLayout`)."""
        self._prepare()
        return self._layout

    def visit_order(self) -> np.ndarray:
        """The cells in the order of a systematic sweep: colour by colour, tile by tile (as
        :attr:`layout` lists them), row-major within a tile, then the long cells. A threaded sweep ends
        in the map this serial order gives."""
        lay = self.layout
        parts = [lay.tile_cells[lay.tile_off[t] : lay.tile_off[t + 1]] for t in lay.col_tiles]
        return np.concatenate([*parts, lay.long_cells]).astype(np.int64)

    def tile_cells(self) -> list[np.ndarray]:
        """The cells of each update group in sweep order: the non-empty tiles (colour by colour), then the
        long cells."""
        lay = self.layout
        return [lay.tile_cells[lay.tile_off[t] : lay.tile_off[t + 1]] for t in lay.col_tiles] + [lay.long_cells]

    def _load_map(self, m: np.ndarray) -> None:
        super()._load_map(m)
        self._inf32 = self._st.inf.view(np.int32)

    def _sweep(self) -> int:
        seed = np.uint64(int(torch.randint(0, 2**63 - 1, (), dtype=torch.int64)))
        self.chain.updates += len(self._visit)
        before = numba.get_num_threads()
        numba.set_num_threads(self.threads)
        try:
            return int(  # threads take a colour's tiles costliest first (par.take_tile)
                par.chromatic_sweep(
                    self._st,
                    self._inf32,
                    self._compiled,
                    self._layout,
                    seed,
                    _SCAN_CODES[self.scan],
                    self._rule,
                    self.threads,
                )
            )
        finally:
            numba.set_num_threads(before)

    def run_marginals(self, num_sweeps: int, seed: int = 0) -> torch.Tensor:
        """Not offered: a chromatic chain runs one sweep per :meth:`sample`."""
        raise NotImplementedError("ChromaticCellGibbs runs one sweep per sample(); use CellGibbs.run_marginals")

    def state_equals_scratch(self) -> bool:
        """Whether the kept first / second hits and likelihood sums equal those computed from scratch
        for the current map (the check that concurrent writes lost nothing)."""
        ref = cs.cell_state_of(self.state, self._index, self._bits)
        return bool(
            np.array_equal(ref.rays, self._st.rays)
            and np.array_equal(ref.d, self._st.d)
            and np.array_equal(ref.inf, self._st.inf)
        )


class ChromaticPatchGibbs(_Threaded, PatchGibbs):
    """Patch Gibbs in chromatic tile sweeps (module docstring), on ``threads`` of numba's threads.

    Args:
        model, patch, scan, offset, p_rand_patch, random_patch, update, init, delta, region, p_escape: as
            :class:`~ogm_ppl.inference.mcmc.gibbs.PatchGibbs` (priors with a compiled face only; ``scan``
            ``"systematic"`` or ``"permutation"``, which order the patches *within* each tile and within the
            long patches).
        tile: the tile side in cells (``None``: the longest ray's extent, at least the prior's factor extent,
            rounded up to a multiple of the patch's height and width). For rectangular patches it must be a
            multiple of both; it must be at least the prior's factor extent.
        threads: numba threads for the sweeps (``None``: numba's current number). The chain does not depend
            on it.
    """

    def __init__(
        self,
        model: OccupancyModel,
        patch=3,
        scan: str = "systematic",
        offset=0,
        p_rand_patch: float = 0.0,
        random_patch: str = "mh",
        update: str = "gibbs",
        init="ogm",
        delta="haehnel",
        region=None,
        p_escape: float = 0.2,
        tile: int | None = None,
        threads: int | None = None,
    ) -> None:
        if scan == "random":
            raise ValueError("ChromaticPatchGibbs orders fixed patches: scan must be 'systematic' or 'permutation'")
        super().__init__(model, patch, scan, offset, p_rand_patch, random_patch, update, init, delta, region, p_escape)
        if tile is not None and int(tile) < 1:
            raise ValueError(f"tile must be a positive number of cells, got {tile}")
        self.tile = None if tile is None else int(tile)
        self.threads = threads

    def _set_up(self) -> None:
        super()._set_up()
        if self._compiled is None:
            raise ValueError("ChromaticPatchGibbs needs a prior with a compiled face (prior.compiled())")
        g = self.model.grid
        h, w = self._hw
        step = int(np.lcm(h, w)) if h else 1
        self.prior_extent = par.prior_extent(self._compiled)
        self.ray_extent = int(par.ray_extents(self._offsets, self._cells, g.cols).max(initial=0))
        if self.tile is None:
            T = max(self.ray_extent, self.prior_extent, step)
            T = -(-T // step) * step
        else:
            T = self.tile
            if h and (T % h or T % w):
                raise ValueError(f"tile {T} must be a multiple of the patch's height {h} and width {w}")
        if T < self.prior_extent:
            raise ValueError(f"tile {T} is smaller than the prior's factor extent {self.prior_extent}")
        origin = (int(self._anchors[:, 0].min()), int(self._anchors[:, 1].min())) if h else (0, 0)
        origin = (min(origin[0], 0), min(origin[1], 0))
        pc = patch_cells(self.model, self._anchors, self.dr, self.dc)
        self._layout = pp.patch_tile_layout(self._anchors, pc, self._index, g.rows, g.cols, T, origin)
        self._bit_of = np.full(0 if kind_of(self._compiled).additive else g.num_cells, -1, np.int64)

    @property
    def layout(self) -> pp.PatchTileLayout:
        """The tiles, their colours and the long patches
        (:class:`~ogm_ppl.inference._kernels.parallel_patch.PatchTileLayout`)."""
        self._prepare()
        return self._layout

    def _sweep(self) -> int:
        seed = np.uint64(int(torch.randint(0, 2**63 - 1, (), dtype=torch.int64)))
        lay = self._layout
        self.chain.updates += len(lay.anchors) + len(lay.long_anchors)
        rows = 5 if self._escapes() else 3
        before = numba.get_num_threads()
        numba.set_num_threads(self.threads)
        try:
            changed, skipped = pp.chromatic_patch_sweep(  # threads take tiles costliest first (par.take_tile)
                self._ps,
                self._geometry(),
                lay,
                self._compiled,
                seed,
                _SCAN_CODES[self.scan],
                self._patch_rule(),
                rows,
                self._bit_of,
                self.threads,
            )
        finally:
            numba.set_num_threads(before)
        if skipped:
            raise RuntimeError(f"{skipped} patch updates had more configurations than fit")
        return int(changed)
