r"""Candidate stops of a stop-and-scan robot: where it can drive on its current map, and how safely.

A robot at cell :math:`s` considers driving to a goal cell :math:`g` along a path :math:`\pi` of 8-connected
cells (no corner cutting). The path is *free* when every cell within ``clearance_cells`` of it (the robot's
body, swept set :math:`W(\pi)`) is free, and its probability under the current map posterior is

.. math::
    P(\pi \text{ free} \mid z) = P(m_c = 0\ \forall c \in W(\pi) \mid z) \approx
    \begin{cases} \frac1S \sum_{s=1}^S \prod_{c \in W(\pi)} [m^{(s)}_c = 0] & \text{samples } m^{(1..S)} \\
    \prod_{c \in W(\pi)} (1 - p_c) & \text{marginals only (cells independent)} \end{cases}

(the exact path probability of :meth:`~ogm_ppl.posterior.MapPosterior.prob_free` for the empirical posterior
of the samples; its cell-independence approximation for a traditional occupancy grid). The cells of the
robot's disk at the start are left out of :math:`W(\pi)`: it stands there already. The thesis's Section
2.6 names this query as what a correlated map answers and an independent one only approximates.

The path itself is the shortest path (Dijkstra, :mod:`scipy.sparse.csgraph`) on the 8-connected graph of
:mod:`ogm_ppl.datasets.stop_and_scan` (its ``_KnownFreeGraph`` over every cell), in which entering cell
:math:`v` costs its step length (cells) plus ``risk_weight`` times :math:`-\log P(\text{disk}(v) \text{
free})` under independent marginals: the risk term is the path's independent-cell :math:`-\log P(\text{free})`
up to the overlap of neighbouring disks, so the path found trades metres for safety. The gate
:math:`P(\pi \text{ free}) \ge` ``threshold`` is then evaluated exactly on that path (samples) or under
independence (marginals).

Candidate goals are the cells of a lattice of ``stride`` cells and the frontier cells (known-free cells with
an unknown 4-neighbour, ``stop_and_scan._frontier``) that pass the gate. Poses are ``(x, y, yaw)`` at cell
centres (metres, radians; yaw 0: a 360 degree scan does not depend on it).
"""

from __future__ import annotations

from dataclasses import dataclass

import numba as nb
import numpy as np
from scipy import ndimage
from scipy.sparse import csgraph, csr_matrix

from ogm_ppl.datasets.stop_and_scan import _frontier, _KnownFreeGraph
from ogm_ppl.grid import Grid

__all__ = [
    "CandidateError",
    "Candidates",
    "PathPlanner",
    "check_candidate_poses",
    "frontier_mask",
    "path_free_probability",
]

_P_MAX = 1.0 - 1e-9  # occupancy clipped here before -log(1 - p): a surely occupied cell costs ~20.7 nats


class CandidateError(ValueError):
    """A candidate stop that cannot be one (off the grid, inside an obstacle) or an empty candidate set."""


@dataclass(frozen=True, eq=False)
class Candidates:
    """Candidate stops and the paths to them.

    Attributes:
        cells: ``C`` int64 flat goal cells (row-major, as :class:`~ogm_ppl.grid.Grid` flattens them).
        poses: ``C x 3`` float64 ``(x, y, yaw)`` at the goal cells' centres (metres, radians).
        distance: ``C`` float64 path lengths in metres.
        p_free: ``C`` float64 ``P(path free | z)`` (module docstring).
        path_offsets, path_cells: the paths in CSR form: path ``i`` is ``path_cells[path_offsets[i]:
            path_offsets[i + 1]]``, flat cells from the start cell to the goal.
        frontier: ``C`` bool, whether the goal is a frontier cell.
    """

    cells: np.ndarray
    poses: np.ndarray
    distance: np.ndarray
    p_free: np.ndarray
    path_offsets: np.ndarray
    path_cells: np.ndarray
    frontier: np.ndarray

    def __len__(self) -> int:
        return int(self.cells.size)

    def path(self, i: int) -> np.ndarray:
        """Flat cells of path ``i``, start to goal."""
        return self.path_cells[self.path_offsets[i] : self.path_offsets[i + 1]]

    def subset(self, keep) -> Candidates:
        """The candidates selected by ``keep`` (a boolean mask or indices), in that order."""
        idx = np.flatnonzero(keep) if np.asarray(keep).dtype == bool else np.asarray(keep, dtype=np.int64)
        lengths = np.diff(self.path_offsets)[idx]
        offs = np.concatenate([[0], np.cumsum(lengths)]).astype(np.int64)
        pos = np.repeat(self.path_offsets[idx] - offs[:-1], lengths) + np.arange(offs[-1])
        cells = self.path_cells[pos]
        return Candidates(
            self.cells[idx],
            self.poses[idx],
            self.distance[idx],
            self.p_free[idx],
            offs,
            cells,
            self.frontier[idx],
        )


# --------------------------------------------------------------------------------------------- checks
def check_candidate_poses(grid: Grid, poses, occupied=None, what: str = "candidate") -> np.ndarray:
    """``poses`` as a ``C x 3`` float64 array, refused (:class:`CandidateError`) when empty, not finite,
    off the grid, or (``occupied``: a ``K`` or grid-shaped bool mask) inside an occupied cell. Errors name the
    first bad pose by index and coordinates."""
    if not isinstance(grid, Grid) or grid.ndim != 2:
        raise CandidateError(f"candidate stops need a 2D ogm_ppl.Grid, got {grid!r}")
    p = np.asarray(poses, dtype=float)
    if p.ndim == 1 and p.size in (2, 3):
        p = p[None]
    if p.ndim != 2 or p.shape[1] not in (2, 3):
        raise CandidateError(f"{what} poses must have shape C x 3 (x, y, yaw) or C x 2, got {p.shape}")
    if p.shape[0] == 0:
        raise CandidateError(f"the {what} set is empty: there is no stop to choose from")
    if p.shape[1] == 2:
        p = np.column_stack([p, np.zeros(len(p))])
    bad = ~np.isfinite(p).all(1)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise CandidateError(f"{what} pose {i} is not finite: {p[i].tolist()}")
    out = ~grid.contains(p[:, :2])
    if out.any():
        i = int(np.flatnonzero(out)[0])
        raise CandidateError(
            f"{what} pose {i} at ({p[i, 0]:g}, {p[i, 1]:g}) m lies off the grid (extent {grid.extent})"
        )
    if occupied is not None:
        occ = np.asarray(occupied, dtype=bool).ravel()
        if occ.size != grid.num_cells:
            raise CandidateError(f"occupied mask has {occ.size} cells, the grid {grid.num_cells}")
        flat = grid.flat_index(grid.world_to_cell(p[:, :2]))
        inside = occ[flat]
        if inside.any():
            i = int(np.flatnonzero(inside)[0])
            r, c = divmod(int(flat[i]), grid.cols)
            raise CandidateError(
                f"{what} pose {i} at ({p[i, 0]:g}, {p[i, 1]:g}) m lies inside an obstacle (cell ({r}, {c}) is occupied)"
            )
    return p


def frontier_mask(grid: Grid, marginals, observed, free_below: float = 0.5) -> np.ndarray:
    """Flat bool ``K``: frontier cells, i.e. observed cells with ``p < free_below`` (known free) that have an
    unobserved 4-neighbour (``stop_and_scan._frontier``)."""
    q = np.asarray(marginals, dtype=float).reshape(grid.shape)
    seen = np.asarray(observed, dtype=bool).reshape(grid.shape)
    return _frontier(seen & (q < free_below), ~seen).ravel()


# --------------------------------------------------------------------------------------------- kernels
@nb.njit(cache=True)
def _trace_paths(pred, source, goals):  # pragma: no cover - compiled
    """CSR of the Dijkstra tree paths ``source -> goal`` (``pred``: predecessors, -9999 at the root / none)."""
    n = goals.size
    lengths = np.zeros(n, np.int64)
    for i in range(n):
        v = goals[i]
        k = 1
        while v != source:
            v = pred[v]
            k += 1
        lengths[i] = k
    offs = np.zeros(n + 1, np.int64)
    for i in range(n):
        offs[i + 1] = offs[i] + lengths[i]
    cells = np.empty(offs[n], np.int64)
    for i in range(n):
        v = goals[i]
        j = offs[i + 1] - 1
        while True:
            cells[j] = v
            if v == source:
                break
            v = pred[v]
            j -= 1
    return offs, cells


@nb.njit(cache=True)
def _swept(offs, cells, rows, cols, dr, dc, skip):  # pragma: no cover - compiled
    """CSR of the swept sets ``W(path)``: unique cells within the disk offsets ``(dr, dc)`` of a path cell,
    leaving out the cells where ``skip`` (``K`` bool) is set."""
    n = offs.size - 1
    stamp = np.full(rows * cols, -1, np.int64)
    out_offs = np.zeros(n + 1, np.int64)
    buf = np.empty(max(1, (offs[n]) * dr.size), np.int64)
    m = 0
    for i in range(n):
        for j in range(offs[i], offs[i + 1]):
            r0, c0 = divmod(cells[j], cols)
            for t in range(dr.size):
                r, c = r0 + dr[t], c0 + dc[t]
                if r < 0 or r >= rows or c < 0 or c >= cols:
                    continue
                v = r * cols + c
                if stamp[v] != i and not skip[v]:
                    stamp[v] = i
                    buf[m] = v
                    m += 1
        out_offs[i + 1] = m
    return out_offs, buf[:m].copy()


@nb.njit(cache=True)
def _p_free_samples(offs, cells, samples):  # pragma: no cover - compiled
    """Share of the sample maps (``S x K`` uint8) in which every cell of each set is free."""
    n, S = offs.size - 1, samples.shape[0]
    out = np.zeros(n)
    for i in range(n):
        free = 0
        for s in range(S):
            ok = True
            for j in range(offs[i], offs[i + 1]):
                if samples[s, cells[j]]:
                    ok = False
                    break
            if ok:
                free += 1
        out[i] = free / S
    return out


def _disk(radius: float) -> tuple[np.ndarray, np.ndarray]:
    r = int(np.floor(radius))
    dr, dc = np.mgrid[-r : r + 1, -r : r + 1]
    keep = dr**2 + dc**2 <= radius**2 + 1e-9
    return dr[keep].astype(np.int64), dc[keep].astype(np.int64)


def _check_map(grid: Grid, marginals, samples):
    q = np.asarray(marginals, dtype=np.float64).ravel()
    if q.size != grid.num_cells:
        raise ValueError(f"marginals have {q.size} cells, the grid {grid.num_cells}")
    if not (np.isfinite(q).all() and (q >= 0).all() and (q <= 1).all()):
        raise ValueError("marginals must be probabilities in [0, 1]")
    if samples is not None:
        s = samples.numpy() if hasattr(samples, "numpy") else np.asarray(samples)
        if s.ndim != 2 or s.shape[1] != grid.num_cells:
            raise ValueError(f"samples must have shape S x {grid.num_cells}, got {s.shape}")
        if s.shape[0] == 0:
            raise ValueError("zero samples: P(path free) needs at least one sample map")
        samples = np.ascontiguousarray(s.astype(np.uint8))
    return q, samples


def path_free_probability(
    grid: Grid,
    path_offsets,
    path_cells,
    *,
    marginals=None,
    samples=None,
    clearance_cells: float = 0.0,
    exclude=None,
) -> np.ndarray:
    r"""``P(path free | z)`` of each path (CSR ``path_offsets`` ``C + 1``, ``path_cells`` flat cells): the
    share of ``samples`` (``S x K``) in which every cell within ``clearance_cells`` of the path is free, or
    (``samples`` None) :math:`\prod_{c \in W} (1 - p_c)` from ``marginals`` (``K``). ``exclude``: flat cells
    left out of every swept set (the robot's own disk: it is there already). ``C`` float64."""
    offs = np.ascontiguousarray(path_offsets, dtype=np.int64)  # contiguous: one compiled _swept for any input
    cells = np.ascontiguousarray(path_cells, dtype=np.int64)
    if cells.size and (cells.min() < 0 or cells.max() >= grid.num_cells):
        raise ValueError(f"path cells must lie in 0..{grid.num_cells - 1}")
    if offs.ndim != 1 or offs.size < 1 or offs[0] != 0 or offs[-1] != cells.size or (np.diff(offs) < 0).any():
        raise ValueError(
            f"path_offsets must run from 0 to len(path_cells) = {cells.size} without decreasing (CSR: path i is "
            f"path_cells[path_offsets[i]:path_offsets[i + 1]]), got {offs.tolist()[:8]}"
        )
    dr, dc = _disk(float(clearance_cells))
    skip = np.zeros(grid.num_cells, dtype=np.bool_)
    if exclude is not None:
        skip[np.asarray(exclude, dtype=np.int64)] = True
    w_offs, w_cells = _swept(offs, cells, grid.rows, grid.cols, dr, dc, skip)
    if samples is not None:
        _, s = _check_map(grid, np.zeros(grid.num_cells), samples)
        return _p_free_samples(w_offs, w_cells, s)
    if marginals is None:
        raise ValueError("give marginals or samples")
    q, _ = _check_map(grid, marginals, None)
    logf = np.log1p(-np.minimum(q, _P_MAX))
    sums = np.add.reduceat(logf[w_cells], w_offs[:-1]) if w_cells.size else np.zeros(offs.size - 1)
    sums[np.diff(w_offs) == 0] = 0.0
    return np.exp(sums)


# --------------------------------------------------------------------------------------------- planner
class PathPlanner:
    """Shortest risk-weighted paths on a grid and the candidate stops they reach (module docstring).

    Args:
        grid: a 2D grid.
        clearance_cells: radius (cells, centre to centre) of the robot's swept disk.
        risk_weight: cells of detour worth one nat of ``-log P(disk free)`` when routing.

    The 8-connected graph (``stop_and_scan._KnownFreeGraph`` over every cell) is built once; each call
    re-weights its edges from the map given.
    """

    def __init__(self, grid: Grid, clearance_cells: float = 1.0, risk_weight: float = 4.0) -> None:
        if not isinstance(grid, Grid) or grid.ndim != 2:
            raise ValueError(f"PathPlanner needs a 2D ogm_ppl.Grid, got {grid!r}")
        if not (np.isfinite(clearance_cells) and clearance_cells >= 0):
            raise ValueError(f"clearance_cells must be a finite number >= 0, got {clearance_cells!r}")
        if not (np.isfinite(risk_weight) and risk_weight >= 0):
            raise ValueError(f"risk_weight must be a finite number >= 0, got {risk_weight!r}")
        self.grid = grid
        self.clearance_cells = float(clearance_cells)
        self.risk_weight = float(risk_weight)
        self._g = _KnownFreeGraph(np.ones(grid.shape, dtype=bool))  # node == flat cell
        self._dr, self._dc = _disk(self.clearance_cells)
        kern = np.zeros((2 * int(self.clearance_cells) + 1,) * 2)
        r = int(self.clearance_cells)
        kern[self._dr + r, self._dc + r] = 1.0
        self._kernel = kern

    def disk_log_free(self, marginals) -> np.ndarray:
        """``K``: ``sum_{c in disk(v)} log(1 - p_c)`` per cell ``v`` (cells off the grid count occupied)."""
        q, _ = _check_map(self.grid, marginals, None)
        logf = np.log1p(-np.minimum(q, _P_MAX)).reshape(self.grid.shape)
        out = ndimage.convolve(logf, self._kernel, mode="constant", cval=np.log1p(-_P_MAX))
        return out.ravel()

    def _start(self, start_cell) -> int:
        """``start_cell`` checked: a flat cell index of the grid (:class:`CandidateError` otherwise)."""
        K = self.grid.num_cells
        v = np.asarray(start_cell)
        if v.ndim != 0 or (v.dtype.kind not in "iu" and not (v.dtype.kind == "f" and float(v).is_integer())):
            raise CandidateError(
                f"start_cell must be one flat cell index (grid.flat_index(grid.world_to_cell(pose[None, :2]))[0]), "
                f"got {start_cell!r}; goal_paths takes the robot's pose"
            )
        if not 0 <= int(v) < K:
            raise CandidateError(f"start_cell {int(v)} lies off the grid (cells 0..{K - 1})")
        return int(v)

    def distances(self, start_cell: int, marginals) -> tuple[np.ndarray, np.ndarray]:
        """Dijkstra from ``start_cell`` on the risk-weighted graph: ``(cost K, predecessors K)``."""
        start_cell = self._start(start_cell)
        g = self._g
        risk = -self.disk_log_free(marginals)
        data = g.w + self.risk_weight * risk[g.dst]
        graph = csr_matrix((data, g.dst, g.indptr), shape=(self.grid.num_cells,) * 2)
        cost, pred = csgraph.dijkstra(graph, directed=True, indices=int(start_cell), return_predecessors=True)
        return cost, pred

    def paths(self, start_cell: int, goals, marginals, samples=None, _dijkstra=None) -> Candidates:
        """The paths from ``start_cell`` to each goal (flat cells) and their ``P(path free)`` (samples when
        given, else the marginals under independence); goals that cannot be reached are dropped."""
        start_cell = self._start(start_cell)
        q, s = _check_map(self.grid, marginals, samples)
        cost, pred = _dijkstra if _dijkstra is not None else self.distances(start_cell, q)
        goals = np.asarray(goals, dtype=np.int64).ravel()
        off = (goals < 0) | (goals >= self.grid.num_cells)
        if off.any():
            raise CandidateError(
                f"goal cell {int(goals[off][0])} lies off the grid (cells 0..{self.grid.num_cells - 1})"
            )
        goals = goals[np.isfinite(cost[goals])]
        offs, cells = _trace_paths(pred.astype(np.int64), int(start_cell), goals)
        steps = np.abs(np.diff(cells))  # 1 or cols: a side step; cols +- 1: a diagonal one
        step_len = np.where((steps == 1) | (steps == self.grid.cols), 1.0, np.sqrt(2.0))
        starts = np.zeros(cells.size, dtype=bool)
        starts[offs[:-1]] = True
        seg = np.where(starts[1:], 0.0, step_len)  # no step between two paths
        cum = np.concatenate([[0.0], np.cumsum(seg)])
        dist = (cum[offs[1:] - 1] - cum[offs[:-1]]) * self.grid.resolution
        sr, sc = divmod(int(start_cell), self.grid.cols)
        r, c = sr + self._dr, sc + self._dc
        inside = (r >= 0) & (r < self.grid.rows) & (c >= 0) & (c < self.grid.cols)
        own = r[inside] * self.grid.cols + c[inside]  # the robot's disk now: not part of any path's risk
        pf = path_free_probability(
            self.grid, offs, cells, marginals=q, samples=s, clearance_cells=self.clearance_cells, exclude=own
        )
        rc = np.stack(np.divmod(goals, self.grid.cols), axis=1)
        poses = np.column_stack([self.grid.cell_to_world(rc), np.zeros(goals.size)]) if goals.size else np.zeros((0, 3))
        return Candidates(goals, poses, dist, pf, offs, cells, np.zeros(goals.size, dtype=bool))

    def goal_paths(self, pose, goal_poses, marginals, samples=None, occupied_above: float = 0.5) -> Candidates:
        """Paths from the robot's ``pose`` to caller-given ``goal_poses`` (``C x 3`` or ``C x 2``, metres).
        Refused (:class:`CandidateError`): an empty set, a pose off the grid, or one inside an obstacle
        (a cell the map holds occupied, ``p > occupied_above``); unreachable goals keep distance inf and
        ``p_free`` 0."""
        q, s = _check_map(self.grid, marginals, samples)
        start = check_candidate_poses(self.grid, pose, q > occupied_above, what="robot")[0]
        goals = check_candidate_poses(self.grid, goal_poses, q > occupied_above)
        gc = self.grid.flat_index(self.grid.world_to_cell(goals[:, :2]))
        sc = int(self.grid.flat_index(self.grid.world_to_cell(start[None, :2]))[0])
        c = self.paths(sc, gc, q, s)
        out_pf = np.zeros(gc.size)
        out_d = np.full(gc.size, np.inf)
        pos = {int(v): i for i, v in enumerate(c.cells)}
        idx = np.array([pos.get(int(v), -1) for v in gc])
        ok = idx >= 0
        out_pf[ok], out_d[ok] = c.p_free[idx[ok]], c.distance[idx[ok]]
        sub = c.subset(idx[ok])
        full_offs = np.zeros(gc.size + 1, np.int64)
        full_offs[1:][ok] = np.diff(sub.path_offsets)
        full_offs = np.cumsum(full_offs)
        return Candidates(gc, goals, out_d, out_pf, full_offs, sub.path_cells, np.zeros(gc.size, dtype=bool))

    def candidates(
        self,
        start_cell: int,
        marginals,
        samples=None,
        *,
        threshold: float = 0.9,
        stride: int | None = 4,
        frontier=None,
        min_distance_cells: float = 0.0,
    ) -> Candidates:
        """Candidate stops: the ``stride`` lattice cells (None: none) and the ``frontier`` cells (flat bool ``K``) whose
        disk is free with probability ``>= threshold`` on their own, that lie at least ``min_distance_cells``
        (Euclidean) from the start, and whose path has ``P(path free) >= threshold``. May be empty."""
        if not 0 < threshold <= 1:
            raise ValueError(f"threshold must lie in (0, 1], got {threshold!r}")
        if stride is not None and (int(stride) != stride or stride < 1):
            raise ValueError(f"stride must be a positive integer or None, got {stride!r}")
        start_cell = self._start(start_cell)
        q, s = _check_map(self.grid, marginals, samples)
        Cc = self.grid.cols
        lattice = np.zeros(self.grid.shape, dtype=bool)
        if stride is not None:
            o = int(stride) // 2
            lattice[o::stride, o::stride] = True
        lattice = lattice.ravel()
        fr = np.zeros(self.grid.num_cells, bool) if frontier is None else np.asarray(frontier, bool).ravel()
        cand = (lattice | fr) & (self.disk_log_free(q) >= np.log(threshold))
        sr, sc = divmod(int(start_cell), Cc)
        rr, cc = np.divmod(np.arange(self.grid.num_cells), Cc)
        cand &= (rr - sr) ** 2 + (cc - sc) ** 2 >= min_distance_cells**2
        cand[int(start_cell)] = False
        dij = self.distances(start_cell, q)
        c = self.paths(start_cell, np.flatnonzero(cand), q, s, _dijkstra=dij)
        keep = c.p_free >= threshold
        c = c.subset(keep)
        return Candidates(c.cells, c.poses, c.distance, c.p_free, c.path_offsets, c.path_cells, fr[c.cells])
