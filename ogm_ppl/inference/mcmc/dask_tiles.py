r"""Chromatic tile sweeps on dask: the tiles of one colour as tasks on a cluster, exactly (Section 4.1).

:class:`DaskTileGibbs` runs the chain of :class:`~ogm_ppl.inference.mcmc.parallel.ChromaticCellGibbs` (same
tiles, colours, scan within a tile and random streams) with each tile's updates as a dask task, so that a map
larger than one machine's memory can be sampled on many: only the driver holds the whole map.

**A tile's sub-problem** (:class:`TileProblem`, built once by :func:`tile_problems` and scattered once to the
workers). Tile ``t``'s update of its cells ``V_t`` reads (a) the rays through ``V_t`` (their cells and
likelihood rows) and (b) the prior's factors through ``V_t``. Let ``W_t`` be the smallest rectangle of the grid
that holds every cell of (a) and every cell within the prior's factor extent ``e_p`` of ``V_t``
(:func:`~ogm_ppl.inference._kernels.parallel.prior_extent`), rounded out to even rows and columns (the pooled
scale of a pattern field pairs cells ``2i, 2i + 1``). The sub-problem is the grid ``W_t`` with those rays
(cells renumbered row-major in ``W_t``), their likelihood rows, the prior's compiled bundle restricted to
``W_t`` (:func:`window_prior`) and the fixed-point scale of the whole model.

**Why a task gives the driver's update bit for bit.** A cell ``k in V_t`` is updated from
``l(m_k | m_-k) + log p(z | m_k = 1, .) - log p(z | m_k = 0, .)``. The prior term reads cells within ``e_p`` of
``k``, all in ``W_t``, and those off the grid are off ``W_t``'s grid too (``W_t`` is clipped only by the grid),
so the restricted bundle gives the same number with the same floating-point operations. The likelihood term is
the kept integer sum ``d_k`` over the rays through ``k`` (:mod:`~ogm_ppl.inference._kernels.cell_sweep`),
and a flip of a cell of ``V_t`` changes only the sums of cells on rays through it: the sub-problem holds every
ray that any update of the task reads or writes, so its sums for ``V_t``, computed from the window's current
values, equal the whole model's (integer sums at one scale are exact). The stream is
:func:`~ogm_ppl.inference._kernels.parallel.tile_seed` of the sweep seed and ``t``, the visiting order the
layout's. So each task returns exactly the values the threaded ``tile_pass`` writes, and the phase (tasks of
one colour, in any order, on any workers) the same map (the phase rule of
:mod:`~ogm_ppl.inference._kernels.parallel`). The chain does not depend on the number of workers.

**What moves.** Per sweep and tile: the window's values to the worker (``|W_t| / 8`` bytes, bit-packed) and the
tile's new values back (``|V_t|`` bytes); the driver applies them to its own state (first / second hits and sums
kept by :func:`~ogm_ppl.inference._kernels.cell_sweep.set_cell`, cost proportional to the flips). A task
rebuilds its sub-problem's hits and sums from the window's values (one pass over its rays) before it sweeps:
workers keep nothing between phases, so a lost worker costs only a resubmitted task.

**Limits.** Every visited cell must be short (no long phase: the default tile, the longest ray's extent,
ensures it). Priors whose factors are a fixed tiling of the grid (patch-table and border priors, the
:class:`~ogm_ppl.priors.compiled.Tiles` bundle) are refused: their tiling is anchored to the whole grid.
``benchmarks/bench_dask_tiles.py`` measures the per-task costs and transfer sizes and models a
``4 x 10^8``-cell map on ``N`` workers.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Sequence
from typing import Any, NamedTuple

import numba as nb
import numpy as np
import torch

from ogm_ppl._raycast_kernels import transpose_csr
from ogm_ppl.inference._kernels import cell_sweep as cs
from ogm_ppl.inference._kernels import parallel as par
from ogm_ppl.inference.mcmc.gibbs import _SCAN_CODES
from ogm_ppl.inference.mcmc.parallel import ChromaticCellGibbs
from ogm_ppl.models.occupancy import OccupancyModel

__all__ = ["DaskTileGibbs", "TileProblem", "run_tile", "run_tiles", "tile_problems", "window_prior"]


class TileProblem(NamedTuple):
    """What a worker holds for tile ``t``: the window ``W_t`` (rows ``r0 .. r0 + rows``, columns
    ``c0 .. c0 + cols`` of the grid), the tile's cells to visit (``visit``, window-local ids in the layout's
    order), the rays through them in CSR form over window-local cells (``offsets``, ``cells``) with the
    transposed index (``c_off``, ``c_ray``, ``c_kappa``) and likelihood rows ``ll``, the prior bundle on the
    window, the fixed-point ``bits``, the scan and update codes."""

    t: int
    r0: int
    c0: int
    rows: int
    cols: int
    visit: np.ndarray  # V int64, window-local
    offsets: np.ndarray  # R_t + 1 int64
    cells: np.ndarray  # nnz_t int64, window-local
    c_off: np.ndarray  # rows * cols + 1 int64
    c_ray: np.ndarray  # nnz_t int64
    c_kappa: np.ndarray  # nnz_t int64
    ll: np.ndarray  # R_t x (F + 1) float64
    prior: Any  # a compiled bundle on the window's grid
    bits: int
    scan: int
    update: int

    @property
    def window_cells(self) -> int:
        """``|W_t|``."""
        return self.rows * self.cols

    def window_of(self, grid_cols: int) -> np.ndarray:
        """The grid ids of the window's cells, row-major (``|W_t|`` int64)."""
        r = np.arange(self.r0, self.r0 + self.rows)[:, None]
        c = np.arange(self.c0, self.c0 + self.cols)[None, :]
        return (r * grid_cols + c).reshape(-1)

    def nbytes(self) -> int:
        """The bytes of the sub-problem's arrays (what scattering it moves, less pickling overhead)."""
        arrays = [self.visit, self.offsets, self.cells, self.c_off, self.c_ray, self.c_kappa, self.ll]
        arrays += [v for v in self.prior if isinstance(v, np.ndarray)]
        return int(sum(a.nbytes for a in arrays))


def window_prior(prior, grid_cols: int, r0: int, c0: int, rows: int, cols: int):
    """The compiled bundle ``prior`` of a grid ``grid_cols`` cells wide, restricted to the window of
    ``rows x cols`` cells at ``(r0, c0)`` by its ``window()`` method: the same conditionals for every cell whose
    factors lie in the window (module docstring). Independent cells and stencils crop their per-cell terms; a
    pattern field needs ``r0``, ``c0`` even (its pooled pairs). Raises ``TypeError`` for a bundle anchored to the
    whole grid (a table prior's tiling) or one without a ``window()``."""
    window = getattr(prior, "window", None)
    if window is None:
        raise TypeError(f"DaskTileGibbs cannot restrict a compiled prior of type {type(prior).__name__} to a window")
    try:
        return window(grid_cols, r0, c0, rows, cols)
    except TypeError as e:
        raise TypeError(f"DaskTileGibbs: {e}") from None


def _ranges(starts: np.ndarray, lengths: np.ndarray) -> np.ndarray:
    """The concatenation of ``arange(s, s + n)`` over ``(s, n)`` pairs, vectorised."""
    total = int(lengths.sum())
    first = np.zeros(len(lengths), np.int64)
    np.cumsum(lengths[:-1], out=first[1:])
    return np.repeat(starts - first, lengths) + np.arange(total, dtype=np.int64)


def tile_problems(kernel: ChromaticCellGibbs) -> list[TileProblem]:
    """The :class:`TileProblem` of every non-empty tile of ``kernel``'s layout, colour by colour in the layout's
    order (``kernel`` prepared: its tiles, state arrays and compiled prior). Raises ``ValueError`` when the
    layout has long cells."""
    kernel._prepare()
    lay = kernel.layout
    if len(lay.long_cells):
        raise ValueError(
            f"{len(lay.long_cells)} visited cells lie on rays that reach two tiles of one colour (tile "
            f"{lay.T}, longest ray extent {kernel.ray_extent}); DaskTileGibbs needs every cell short: use "
            f"tile >= {kernel.ray_extent}"
        )
    rows, cols = lay.rows, lay.cols
    prior = kernel._compiled
    e_p = kernel.prior_extent
    off, cells, c_off, c_ray, ll = kernel._offsets, kernel._cells, kernel._c_off, kernel._c_ray, kernel._ll
    scan, rule = _SCAN_CODES[kernel.scan], kernel._rule
    out = []
    for t in lay.col_tiles:
        v = lay.tile_cells[lay.tile_off[t] : lay.tile_off[t + 1]]
        # the rays through the tile's cells, in increasing order
        rays = np.unique(c_ray[_ranges(c_off[v], c_off[v + 1] - c_off[v])])
        lengths = off[rays + 1] - off[rays]
        r_off = np.zeros(len(rays) + 1, np.int64)
        np.cumsum(lengths, out=r_off[1:])
        g_cells = cells[_ranges(off[rays], lengths)]
        vr, vc = np.divmod(v, cols)
        rr, cc = np.divmod(g_cells, cols)
        lo_r = min(int(vr.min()) - e_p, int(rr.min(initial=rows)))
        hi_r = max(int(vr.max()) + e_p, int(rr.max(initial=-1)))
        lo_c = min(int(vc.min()) - e_p, int(cc.min(initial=cols)))
        hi_c = max(int(vc.max()) + e_p, int(cc.max(initial=-1)))
        r0, c0 = max(0, lo_r) // 2 * 2, max(0, lo_c) // 2 * 2
        r1, c1 = min(rows, (hi_r + 2) // 2 * 2), min(cols, (hi_c + 2) // 2 * 2)
        wr, wc = r1 - r0, c1 - c0
        loc = (rr - r0) * wc + (cc - c0)
        l_off, l_ray, l_kap = transpose_csr(r_off, np.ascontiguousarray(loc), wr * wc)
        out.append(
            TileProblem(
                t=int(t),
                r0=r0,
                c0=c0,
                rows=wr,
                cols=wc,
                visit=np.ascontiguousarray((vr - r0) * wc + (vc - c0)),
                offsets=r_off,
                cells=np.ascontiguousarray(loc),
                c_off=l_off,
                c_ray=l_ray,
                c_kappa=l_kap,
                ll=np.ascontiguousarray(ll[rays]),
                prior=window_prior(prior, cols, r0, c0, wr, wc),
                bits=int(kernel._bits),
                scan=int(scan),
                update=int(rule),
            )
        )
    return out


def _window(grid: np.ndarray, p: TileProblem) -> np.ndarray:
    """The window's values of the ``rows x cols`` map ``grid``, row-major (a copy)."""
    return grid[p.r0 : p.r0 + p.rows, p.c0 : p.c0 + p.cols]


@nb.njit(cache=True)
def _apply(st, cells, values):
    """``m[cells] = values``, keeping the hits and sums in step (:func:`~ogm_ppl.inference._kernels.cell_sweep
    .set_cell`)."""
    for i in range(cells.shape[0]):
        cs.set_cell(st, cells[i], values[i])


@nb.njit(cache=True)
def _tile_draws(visit, scan, seed, t):
    """Tile ``t``'s order and uniforms in the sweep of seed ``seed``: those of ``tile_pass``."""
    return cs.draws(visit, scan, par.tile_seed(seed, t))


def run_tile(problem: TileProblem, packed: np.ndarray, seed: int) -> tuple[np.ndarray, int]:
    """One task: tile ``problem.t``'s updates in the sweep of seed ``seed``, from the window's current values
    (``packed``: ``np.packbits`` of the ``|W_t|`` values, row-major). Returns the tile's new values (uint8, in
    ``problem.visit``'s order) and the number of flips."""
    m = np.unpackbits(packed, count=problem.window_cells)
    st = cs.cell_state(
        m, problem.offsets, problem.cells, problem.c_off, problem.c_ray, problem.c_kappa, problem.ll, problem.bits
    )
    order, u = _tile_draws(problem.visit, problem.scan, np.uint64(seed), problem.t)
    flips = cs.sweep(st, order, problem.prior, u, problem.update)
    return st.m[problem.visit], int(flips)


def run_tiles(problems: Sequence[TileProblem], packed: Sequence[np.ndarray], seed: int) -> list:
    """One task of several tiles of one colour: :func:`run_tile` on each, in turn."""
    return [run_tile(p, x, seed) for p, x in zip(problems, packed, strict=True)]


class DaskTileGibbs(ChromaticCellGibbs):
    """The chain of :class:`~ogm_ppl.inference.mcmc.parallel.ChromaticCellGibbs` with each tile's updates a
    dask task (module docstring): a ``pyro.infer.MCMC`` kernel over site ``"m"`` like every map kernel.

    Args:
        model, scan, update, init, delta, region, tile: as ``ChromaticCellGibbs`` (every visited cell must be
            short: ``tile`` at least the longest ray's extent, the default).
        client: a ``distributed.Client`` (``None``: a local cluster of ``workers`` single-threaded worker
            processes, closed by :meth:`close`), or a scheduler's address (``"host:port"``).
        workers: the local cluster's workers (``None``: one per core).
        tiles_per_task: tiles of one colour run by one task, one after another (consecutive in the layout's
            order, scattered together): fewer, larger tasks cut the scheduler's round trips, which bound a
            sweep on many workers (``benchmarks/bench_dask_tiles.py``). The chain does not depend on it.

    The sub-problems are built and scattered at the first sweep; per sweep the driver submits the tasks of one
    colour, waits for them and applies their values, four colours in turn. :attr:`last_sweep` records the
    bytes sent and received and the seconds of the last sweep's phases.
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
        client=None,
        workers: int | None = None,
        tiles_per_task: int = 1,
    ) -> None:
        super().__init__(model, scan, update, init, delta, region, tile, threads=1)
        if workers is not None and int(workers) < 1:
            raise ValueError(f"workers must be a positive number, got {workers}")
        if int(tiles_per_task) < 1:
            raise ValueError(f"tiles_per_task must be a positive number, got {tiles_per_task}")
        self.tiles_per_task = int(tiles_per_task)
        self._client_arg = client
        self.workers = None if workers is None else int(workers)
        self._client = None
        self._owned = False
        self._problems: list[TileProblem] | None = None
        self._futures: list | None = None
        self._visits: list[np.ndarray] | None = None
        self.last_sweep: dict[str, Any] = {}

    # ----------------------------------------------------------------- cluster
    @property
    def client(self):
        """The ``distributed.Client`` the sweeps run on (started at the first use)."""
        if self._client is None:
            from distributed import Client, LocalCluster

            c = self._client_arg
            if c is None:
                cluster = LocalCluster(
                    n_workers=self.workers,
                    threads_per_worker=1,
                    processes=True,
                    dashboard_address=None,
                    silence_logs=logging.ERROR,
                )
                self._client, self._owned = Client(cluster), True
            elif isinstance(c, str):
                self._client, self._owned = Client(c), True
            else:
                self._client = c
        return self._client

    def close(self) -> None:
        """Release the scattered sub-problems, and close the client (and its cluster) if this kernel started it."""
        if self._futures is not None and self._client is not None:
            self._client.cancel(self._futures)
        self._futures = None
        if self._owned and self._client is not None:
            cluster = self._client.cluster
            self._client.close()
            if cluster is not None:
                cluster.close()
        self._client, self._owned = None, False

    def __enter__(self) -> DaskTileGibbs:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def __getstate__(self) -> dict:
        d = self.__dict__.copy()
        d["_client"] = d["_futures"] = None
        d["_owned"] = False
        return d

    # ----------------------------------------------------------------- sweeps
    @property
    def problems(self) -> list[TileProblem]:
        """The tiles' sub-problems, colour by colour (:func:`tile_problems`)."""
        if self._problems is None:
            self._prepare()
            self._problems = tile_problems(self)
            cols = self.model.grid.cols
            self._visits = [p.window_of(cols)[p.visit] for p in self._problems]
        return self._problems

    def _groups(self) -> list[list[range]]:
        """Per colour, the ranges of problem indices each task runs."""
        lay, n = self.layout, self.tiles_per_task
        out = []
        for colour in range(par.COLOURS):
            a, b = int(lay.col_off[colour]), int(lay.col_off[colour + 1])
            out.append([range(j, min(j + n, b)) for j in range(a, b, n)])
        return out

    def _scatter(self) -> list:
        if self._futures is None:
            problems = self.problems
            batches = [tuple(problems[j] for j in g) for groups in self._groups() for g in groups]
            self._futures = self.client.scatter(batches, broadcast=False)
        return self._futures

    def _sweep(self) -> int:
        seed = int(torch.randint(0, 2**63 - 1, (), dtype=torch.int64))
        self.chain.updates += len(self._visit)
        futures = self._scatter()
        problems, visits = self.problems, self._visits
        assert visits is not None  # set with the problems
        lay = self.layout
        m = self.state
        grid = m.reshape(lay.rows, lay.cols)
        sent = received = flips = 0
        phases = []
        f = 0
        for groups in self._groups():
            if not groups:
                continue
            t0 = time.perf_counter()
            packed = [[np.packbits(_window(grid, problems[j])) for j in g] for g in groups]
            sent += sum(x.nbytes for p in packed for x in p)
            tasks = self.client.map(run_tiles, futures[f : f + len(groups)], packed, [seed] * len(groups), pure=False)
            f += len(groups)
            for g, results in zip(groups, self.client.gather(tasks), strict=True):
                for j, (values, n) in zip(g, results, strict=True):
                    received += values.nbytes
                    flips += n
                    cells = visits[j]
                    changed = np.nonzero(values != m[cells])[0]
                    _apply(self._st, cells[changed], values[changed])
            phases.append(time.perf_counter() - t0)
        self.last_sweep = {"bytes_sent": sent, "bytes_received": received, "phase_s": phases, "flips": flips}
        return flips

    def run_marginals(self, num_sweeps: int, seed: int = 0) -> torch.Tensor:
        """Not offered: a tile chain runs one sweep per :meth:`sample`."""
        raise NotImplementedError("DaskTileGibbs runs one sweep per sample(); use CellGibbs.run_marginals")
