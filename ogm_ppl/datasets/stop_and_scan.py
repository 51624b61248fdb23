r"""Simulated stop-and-scan datasets on any ground-truth map, as in the thesis's Section 6.1.

The thesis simulated its 2D datasets in Player/Stage: "a simple exploration algorithm is used to ensure
coverage", and the robot "only maps the environment when stopped", measuring 360 degrees around itself at
each stop, with a maximum range of :math:`F = 75` cells and Gaussian range noise
:math:`p(z_n | f) = \mathcal{N}(f, 3^2)` (in cells). The exploration algorithm itself is not given, so
this module supplies one:

:func:`plan_route`
    greedy frontier exploration. The robot knows what a noise-free 360 degree sensor of range ``F`` has
    shown it so far; a *frontier* is a known-free cell next to an unknown one. From each stop the robot
    drives to a pose next to a frontier: of the goals (nearest pose within a few cells of a frontier
    cluster) of the eight geodesically nearest clusters -- geodesic through known-free cells that keep
    ``clearance_cells`` from every wall and from the grid edge -- the one with the most new free cells
    per distance, :math:`\text{gain} / (d + F)`, where the gain is what its scan would show (predicted
    from the ground truth, as the simulator can) and must be at least 2% of the disc :math:`\pi F^2`.
    It scans there and repeats until the share of observed free cells reaches ``coverage``, ``num_poses``
    stops are placed, or no frontier is left that is reachable and worth a stop.
:func:`drive_route`
    the poses of a robot that scans while it drives: the geodesically shortest paths between consecutive
    stops (through cells that keep ``clearance_cells`` from the walls), a pose every ``step_cells`` of path
    length, facing the direction of travel (real logs such as the Intel Lab's: a front-facing scanner
    read every half metre or so).
:func:`stop_and_scan`
    the route plus simulated scans (:func:`~ogm_ppl.datasets.simulate.simulate_scans`): 720 beams over
    360 degrees, ``F = 75`` cells, ``sigma = 3`` cells by default; sparser variants keep an evenly spaced
    subset of the stops (``pose_fraction``) or of the beams (``beam_step``). Each stop's noise comes from
    its own seeded stream and all beams are drawn before thinning, so a sparser dataset's readings are
    exactly a subset of the full dataset's readings for the same seed.

Poses are ``P x 3`` arrays of ``(x, y, yaw)`` in metres and radians; the yaw is the direction of travel
into the stop (0 at the start), which does not matter for a 360 degree scan.

>>> from ogm_ppl import Grid
>>> truth = np.zeros((60, 60), bool); truth[[0, -1], :] = truth[:, [0, -1]] = True
>>> truth[:, 30] = True; truth[25:35, 30] = False  # two rooms and a doorway
>>> grid = Grid(truth.shape, resolution=0.05)
>>> data = stop_and_scan(truth, grid, max_range_cells=40, seed=1)
>>> data.scans.beams_per_scan, route_coverage(truth, grid, data.route, max_range_cells=40) >= 0.95
(720, True)
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy import ndimage
from scipy.sparse import csgraph, csr_matrix

from ogm_ppl.datasets.simulate import first_hit, simulate_scans
from ogm_ppl.grid import Grid
from ogm_ppl.raycast import raycast
from ogm_ppl.scans import Scans

__all__ = ["StopAndScan", "drive_route", "plan_route", "route_coverage", "stop_and_scan"]

_BIG = 1e9  # weight of an edge through a cell the robot has not seen free yet
_EIGHT = np.ones((3, 3), dtype=bool)


@dataclass(frozen=True, eq=False)
class StopAndScan:
    """A simulated stop-and-scan dataset.

    Attributes:
        scans: the readings (``S x B``), taken at ``route[settings["pose_indices"]]``.
        route: the full planned route (``P x 3``, metres/radians); a sparser variant scans at a subset of it.
        truth: the ground-truth map (``rows x cols`` bool, True = occupied).
        grid: the grid of ``truth``.
        settings: the arguments and derived values (plain JSON-able numbers and lists).
    """

    scans: Scans
    route: np.ndarray
    truth: np.ndarray
    grid: Grid
    settings: dict = field(default_factory=dict)


# --------------------------------------------------------------------------- checks
def _check_truth(truth, grid: Grid) -> np.ndarray:
    if not isinstance(grid, Grid):
        raise TypeError(f"grid must be an ogm_ppl.Grid, got {type(grid).__name__}")
    if grid.ndim != 2:
        raise ValueError(f"stop-and-scan datasets need a 2D grid, got shape {grid.shape}")
    truth = np.asarray(truth)
    if truth.shape != grid.shape:
        raise ValueError(f"truth has shape {truth.shape}, the grid {grid.shape}")
    truth = truth.astype(bool)
    if truth.all():
        raise ValueError("truth has no free cell: there is nowhere to put the robot")
    return truth


def _check_positive(name: str, value: float) -> float:
    value = float(value)
    if not np.isfinite(value) or value <= 0:
        raise ValueError(f"{name} must be a positive finite number, got {value!r}")
    return value


# --------------------------------------------------------------------------- geometry
def _check_clearance(clearance_cells: float) -> float:
    clearance_cells = float(clearance_cells)
    if not np.isfinite(clearance_cells) or clearance_cells < 0:
        raise ValueError(f"clearance_cells must be a finite number >= 0, got {clearance_cells!r}")
    return clearance_cells


def _clear_cells(truth: np.ndarray, clearance_cells: float) -> np.ndarray:
    """``rows x cols`` bool: cells whose centre lies more than ``clearance_cells`` (Euclidean, centre to centre)
    from every occupied cell and from the outside of the grid."""
    return ndimage.distance_transform_edt(np.pad(~truth, 1))[1:-1, 1:-1] > clearance_cells


def _num_probe_beams(max_range_cells: float) -> int:
    # 720 beams (the thesis) leave no gap at F = 75; keep the arc between beams <= 2/3 cell for larger F.
    return max(720, int(np.ceil(1.5 * 2 * np.pi * max_range_cells)))


def _observe(grid: Grid, truth: np.ndarray, poses: np.ndarray, max_range_cells: float) -> np.ndarray:
    """Flat boolean ``K``: cells a noise-free 360 degree scan from each pose reaches (up to and including
    the first occupied cell of each beam)."""
    B = _num_probe_beams(max_range_cells)
    angles = np.arange(B) * (2 * np.pi / B)
    max_range = max_range_cells * grid.resolution
    poses = np.atleast_2d(poses)
    seen = np.zeros(grid.num_cells, dtype=bool)
    for p in poses:  # one pose at a time keeps the ray structure small
        rays = raycast(grid, Scans(p, angles, np.full(B, max_range), max_range))
        f = first_hit(rays, truth)
        seen[rays.cells[rays.kappa <= np.repeat(f, rays.lengths)]] = True
    return seen


def _free_component(free: np.ndarray, cells: np.ndarray) -> np.ndarray:
    """Free cells 4-connected (a beam crosses cell faces) to any of ``cells`` (``N x 2``)."""
    lab, _ = ndimage.label(free)
    ids = np.unique(lab[cells[:, 0], cells[:, 1]])
    return np.isin(lab, ids[ids > 0])


def route_coverage(truth, grid: Grid, route, *, max_range_cells: float = 75) -> float:
    """Share of the free cells around the route (its 4-connected free component) that noise-free 360 degree
    scans of range ``max_range_cells`` from the route's poses observe.

    >>> from ogm_ppl import Grid
    >>> t = np.zeros((10, 10), bool); t[:, 5] = True
    >>> route_coverage(t, Grid((10, 10)), [[1.5, 1.5, 0.0]], max_range_cells=20)
    1.0
    """
    truth = _check_truth(truth, grid)
    max_range_cells = _check_positive("max_range_cells", max_range_cells)
    route = np.atleast_2d(np.asarray(route, dtype=float))
    if route.size == 0:
        return 0.0
    cells = grid.world_to_cell(route[:, :2])
    target = _free_component(~truth, cells).ravel()
    if not target.any():
        raise ValueError("the route's poses all lie in occupied cells")
    seen = _observe(grid, truth, route, max_range_cells)
    return float((seen & target).sum() / target.sum())


class _KnownFreeGraph:
    """The 8-connected graph of the cells of ``mask`` (no corner cutting), in which a step costs its length
    once both its cells are known free and ``_BIG`` before; distances below ``_BIG / 2`` are paths through
    known-free cells only. Edge costs are updated in place as cells become known."""

    def __init__(self, mask: np.ndarray):
        rows, cols = mask.shape
        n = int(mask.sum())
        self.cell = np.flatnonzero(mask.ravel())  # node -> flat cell
        self.node = np.full(mask.size, -1, dtype=np.int64)  # flat cell -> node
        self.node[self.cell] = np.arange(n)
        node = self.node.reshape(mask.shape)
        srcs, dsts, ws = [], [], []
        for dr, dc in ((0, 1), (1, 0), (1, 1), (1, -1)):
            c0, c1 = max(0, -dc), cols - max(0, dc)
            a = node[0 : rows - dr, c0:c1]
            b = node[dr:rows, c0 + dc : c1 + dc]
            ok = (a >= 0) & (b >= 0)
            if dr and dc:  # a diagonal step needs both side cells
                ok &= mask[0 : rows - dr, c0 + dc : c1 + dc] & mask[dr:rows, c0:c1]
            srcs.append(a[ok])
            dsts.append(b[ok])
            ws.append(np.full(int(ok.sum()), np.hypot(dr, dc)))
        m = sum(x.size for x in srcs)
        src, dst, w = np.concatenate(srcs + dsts), np.concatenate(dsts + srcs), np.concatenate(ws + ws)
        rev = np.concatenate([np.arange(m, 2 * m), np.arange(m)])  # e and rev[e] join the same cells
        order = np.lexsort((dst, src))  # canonical CSR: scipy would sort it in place otherwise
        self.dst, self.w = dst[order], w[order]
        self.rev = np.argsort(order)[rev[order]]
        self.indptr = np.concatenate([[0], np.cumsum(np.bincount(src, minlength=n))])
        self.known = np.zeros(n, dtype=bool)
        self.version = 0
        self._cache: tuple[tuple[int, int], float, np.ndarray] | None = None
        self.graph = csr_matrix((np.full(self.w.size, _BIG), self.dst, self.indptr), shape=(n, n))

    def update(self, known_free: np.ndarray) -> None:
        """Open the steps between cells that ``known_free`` (flat bool over the grid) marks."""
        new = np.flatnonzero(known_free[self.cell] & ~self.known)
        if new.size == 0:
            return
        self.known[new] = True
        self.version += 1
        lo, hi = self.indptr[new], self.indptr[new + 1]
        pos = np.repeat(lo - np.concatenate([[0], np.cumsum(hi - lo)[:-1]]), hi - lo)
        pos += np.arange(pos.size)
        pos = pos[self.known[self.dst[pos]]]
        self.graph.data[pos] = self.w[pos]
        self.graph.data[self.rev[pos]] = self.w[pos]

    def distances(self, source: int, limit: float) -> np.ndarray:
        """Geodesic distance (cells) through known-free cells from node ``source``; inf beyond ``limit``.
        Cached until the source or the known cells change."""
        key = (source, self.version)
        if self._cache is not None and self._cache[0] == key and self._cache[1] >= limit:
            d = self._cache[2]
            return np.where(d <= limit, d, np.inf)
        d = csgraph.dijkstra(self.graph, indices=source, limit=min(limit, _BIG / 2))
        d[d >= _BIG / 2] = np.inf
        self._cache = (key, limit, d)
        return d


def _frontier(known_free: np.ndarray, unknown: np.ndarray) -> np.ndarray:
    """Known-free cells with an unknown 4-neighbour."""
    near = np.zeros_like(unknown)
    near[1:] |= unknown[:-1]
    near[:-1] |= unknown[1:]
    near[:, 1:] |= unknown[:, :-1]
    near[:, :-1] |= unknown[:, 1:]
    return known_free & near


def _gains(grid: Grid, truth, cells: np.ndarray, unseen: np.ndarray, max_range_cells: float) -> np.ndarray:
    """New cells of ``unseen`` (flat bool) that a noise-free scan (240 beams) from each cell centre would
    observe (``len(cells)`` int64); all scans in one ray cast."""
    B = 240
    S = cells.size
    rc = np.stack(np.divmod(cells, grid.cols), axis=1)
    poses = np.column_stack([grid.cell_to_world(rc), np.zeros(S)])
    max_range = max_range_cells * grid.resolution
    angles = np.arange(B) * (2 * np.pi / B)
    rays = raycast(grid, Scans(poses, angles, np.full((S, B), max_range), max_range))
    f = first_hit(rays, truth)
    keep = rays.kappa <= np.repeat(f, rays.lengths)
    c = rays.cells[keep]
    s = rays.ray_of_entry[keep] // B
    new = unseen[c]
    key = np.unique(s[new] * grid.num_cells + c[new])
    return np.bincount(key // grid.num_cells, minlength=S)


def _kill_near(dead, seen, free, grid: Grid, cell_flat: int, reach: float) -> None:
    """Give up the frontier cells within ``reach`` (Chebyshev, as goals are chosen) of a stop whose scan did
    not resolve them (a grazed wall, a gap the robot cannot pass), or of a goal that would show too little:
    that cell stops being a goal for those frontier cells."""
    rr = int(reach)
    r, c = divmod(int(cell_flat), grid.cols)
    r0, r1 = max(0, r - rr), min(grid.rows, r + rr + 1)
    c0, c1 = max(0, c - rr), min(grid.cols, c + rr + 1)
    # the frontier of a window one cell larger, so that the window's edge makes no false frontier
    R0, R1, C0, C1 = max(0, r0 - 1), min(grid.rows, r1 + 1), max(0, c0 - 1), min(grid.cols, c1 + 1)
    sw = seen.reshape(grid.shape)[R0:R1, C0:C1]
    f = _frontier(sw & free[R0:R1, C0:C1], ~sw)[r0 - R0 : r1 - R0, c0 - C0 : c1 - C0]
    dead.reshape(grid.shape)[r0:r1, c0:c1] |= f


def _next_goal(
    grid,
    truth,
    free,
    seen,
    dead,
    target,
    graph: _KnownFreeGraph,
    current,
    *,
    reach,
    min_cluster,
    min_gain,
    max_range_cells,
    k_eval=8,
    whole_grid=False,
):
    """The next stop (a graph node), -1 after giving up frontiers, or None when nothing is left.

    Frontier cells are grouped in 8-connected clusters; clusters of at least ``min_cluster`` cells come
    first. A cluster's goal is its geodesically nearest known-free node within ``reach`` cells (Chebyshev)
    of it. Of the ``k_eval`` nearest goals, the one with the most new free cells per distance travelled,
    ``gain / (distance + F)``, wins among those whose scan would show at least ``min_gain`` new free cells;
    when none would, the frontier cells near them are given up and the next ``k_eval`` goals are tried.
    ``whole_grid`` searches the whole grid instead of the known-free cells' window (the same goal; a reference
    for tests and benchmarks).
    """
    shape = grid.shape
    known_free = (seen & free.ravel()).reshape(shape)
    # Every frontier cell is known free, so the frontier, its clusters and the cells within reach of them lie
    # in the known-free cells' bounding box grown by reach + 1: the work is done on that window. Its edge
    # makes no false frontier (no known-free cell lies on it but at the grid's edge), cluster ids keep the
    # whole grid's (row-major) order, and the maximum filter is exact inside it (zeros beyond, as outside).
    rows, cols = np.flatnonzero(known_free.any(1)), np.flatnonzero(known_free.any(0))
    if rows.size == 0:
        return None
    m = int(reach) + 1
    win = (
        (slice(None), slice(None))
        if whole_grid
        else (
            slice(max(0, rows[0] - m), min(shape[0], rows[-1] + m + 1)),
            slice(max(0, cols[0] - m), min(shape[1], cols[-1] + m + 1)),
        )
    )
    frontier = _frontier(known_free[win], ~seen.reshape(shape)[win]) & ~dead.reshape(shape)[win]
    if not frontier.any():
        return None
    fl, nf = ndimage.label(frontier, structure=_EIGHT)
    sizes = np.bincount(fl.ravel(), minlength=nf + 1)
    sizes[0] = 0
    # large clusters get the larger ids, so the maximum filter prefers them where clusters meet
    ranked = np.where(sizes[fl] >= min_cluster, fl + nf, fl)
    near = np.zeros(shape, dtype=ranked.dtype)
    near[win] = ndimage.maximum_filter(ranked, size=2 * int(reach) + 1, mode="constant")
    cluster = near.ravel()[graph.cell]  # per node: a frontier cluster within reach (0: none)
    cand = graph.known & (cluster > 0)
    cand[current] = False
    if not cand.any():
        return None
    for limit in (max_range_cells, 4.0 * max_range_cells, np.inf):
        d = np.where(cand, graph.distances(current, limit), np.inf)
        if np.isfinite(d).any():
            break
    else:
        return None  # the remaining frontiers lie beyond unseen space
    ok = np.flatnonzero(np.isfinite(d))
    order = ok[np.argsort(d[ok], kind="stable")]
    _, first = np.unique(cluster[order], return_index=True)
    reps = order[np.sort(first)]  # one goal per cluster, nearest first
    large = cluster[reps] > nf
    reps = np.concatenate([reps[large], reps[~large]])
    unseen = ~seen & target
    for i in range(0, reps.size, k_eval):  # the next k_eval goals while those before show too little
        chunk = reps[i : i + k_eval]
        gains = _gains(grid, truth, graph.cell[chunk], unseen, max_range_cells)
        if gains.max() >= min_gain:
            score = np.where(gains >= min_gain, gains / (d[chunk] + max_range_cells), -1.0)
            return int(chunk[np.argmax(score)])
        for cell in graph.cell[chunk]:
            _kill_near(dead, seen, free, grid, cell, reach)
    return -1


# --------------------------------------------------------------------------- route
def plan_route(
    truth,
    grid: Grid,
    *,
    start=None,
    num_poses: int | None = None,
    coverage: float = 0.95,
    max_range_cells: float = 75,
    clearance_cells: float = 2,
    seed: int = 0,
) -> np.ndarray:
    r"""A seeded exploration route over the free space of ``truth`` (greedy nearest-frontier exploration).

    Args:
        truth: ground-truth map, ``rows x cols`` bool (True = occupied), of ``grid.shape``.
        grid: a 2D :class:`~ogm_ppl.grid.Grid`.
        start: ``(x, y)`` or ``(x, y, yaw)`` in metres; default: a seeded random cell of the largest
            connected region of cells with clearance.
        num_poses: the most stops to place (default: no limit).
        coverage: stop once this share of the free cells around the start (its 4-connected component)
            has been observed, in ``(0, 1]``.
        max_range_cells: range ``F`` of the simulated 360 degree sensor, in cells.
        clearance_cells: every pose's cell centre lies more than this many cells (Euclidean, centre to
            centre) from every occupied cell and from the outside of the grid.
        seed: picks the default start and a sub-cell jitter (within a quarter cell of the cell centre).

    Returns:
        ``P x 3`` poses ``(x, y, yaw)`` in metres and radians; all lie in free cells with clearance, in one
        8-connected region of such cells (each stop is reachable from the start). The route stops early
        when no frontier can be reached any more, whatever ``coverage`` asks.

    Raises:
        ValueError: ``truth`` does not match the grid, has no free cell or no cell with clearance; the start
            lies outside the grid, in an occupied cell or too close to a wall; a bad argument.
    """
    truth = _check_truth(truth, grid)
    max_range_cells = _check_positive("max_range_cells", max_range_cells)
    coverage = float(coverage)
    if not 0 < coverage <= 1:
        raise ValueError(f"coverage must lie in (0, 1], got {coverage!r}")
    clearance_cells = _check_clearance(clearance_cells)
    if num_poses is not None:
        if int(num_poses) != num_poses or num_poses < 1:
            raise ValueError(f"num_poses must be a positive integer or None, got {num_poses!r}")
        num_poses = int(num_poses)
    rng = np.random.default_rng(seed)
    free = ~truth
    valid = _clear_cells(truth, clearance_cells)
    if not valid.any():
        raise ValueError(f"no free cell keeps clearance_cells = {clearance_cells} from the walls and the grid edge")
    lab, _ = ndimage.label(valid, structure=_EIGHT)

    # ---- start
    if start is None:
        sizes = np.bincount(lab.ravel())
        sizes[0] = 0
        cells = np.flatnonzero(lab.ravel() == np.argmax(sizes))
        s = int(cells[rng.integers(cells.size)])
        start_cell = np.array([s // grid.cols, s % grid.cols])
        yaw0 = 0.0
    else:
        start = np.asarray(start, dtype=float).ravel()
        if start.shape not in ((2,), (3,)) or not np.all(np.isfinite(start)):
            raise ValueError(f"start must be finite (x, y) or (x, y, yaw), got {start.tolist()}")
        if not grid.contains(start[None, :2])[0]:
            raise ValueError(f"start {start[:2].tolist()} lies outside the grid (extent {grid.extent})")
        start_cell = grid.world_to_cell(start[None, :2])[0]
        if truth[tuple(start_cell)]:
            raise ValueError(f"start {start[:2].tolist()} lies in an occupied cell (inside a wall)")
        if not valid[tuple(start_cell)]:
            raise ValueError(f"start {start[:2].tolist()} lies within clearance_cells = {clearance_cells} of a wall")
        yaw0 = float(start[2]) if start.shape == (3,) else 0.0
    comp = lab == lab[tuple(start_cell)]
    target = _free_component(free, start_cell[None, :]).ravel()
    n_target = int(target.sum())

    graph = _KnownFreeGraph(comp)
    res = grid.resolution
    reach = clearance_cells + 2.0  # a goal lies this close (cells, Chebyshev) to a frontier cell
    min_cluster = max(5, int(np.ceil(2 * clearance_cells + 1)))  # cells; a door the robot fits
    min_gain = max(1, round(0.02 * np.pi * max_range_cells**2))  # new free cells a stop must show

    def pose_at(cell_flat: int | np.ndarray, yaw: float) -> np.ndarray:
        r, c = divmod(int(cell_flat), grid.cols)
        xy = grid.cell_to_world(np.array([[r, c]]))[0] + rng.uniform(-0.25, 0.25, 2) * res
        return np.array([xy[0], xy[1], yaw])

    route = [pose_at(grid.flat_index(start_cell), yaw0)]
    if start is not None:
        route[0][:2] = start[:2]  # keep the caller's start exactly
    seen = _observe(grid, truth, route[0], max_range_cells)
    dead = np.zeros(grid.num_cells, dtype=bool)
    current = int(graph.node[grid.flat_index(start_cell)])
    _kill_near(dead, seen, free, grid, graph.cell[current], reach)
    graph.update(seen & free.ravel())
    need = coverage * n_target
    while (seen & target).sum() < need and (num_poses is None or len(route) < num_poses):
        goal = _next_goal(
            grid,
            truth,
            free,
            seen,
            dead,
            target,
            graph,
            current,
            reach=reach,
            min_cluster=min_cluster,
            min_gain=min_gain,
            max_range_cells=max_range_cells,
        )
        if goal is None:
            break
        if goal < 0:  # frontiers given up; look again
            continue
        prev = route[-1]
        cell = graph.cell[goal]
        p = pose_at(cell, 0.0)
        p[2] = float(np.arctan2(p[1] - prev[1], p[0] - prev[0]))
        route.append(p)
        seen |= _observe(grid, truth, p, max_range_cells)
        graph.update(seen & free.ravel())
        _kill_near(dead, seen, free, grid, cell, reach)
        current = goal
    return np.array(route)


def _nearest(sorted_values: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Index of the entry of ``sorted_values`` nearest each ``x`` (the lower one on a tie)."""
    if len(sorted_values) == 1:
        return np.zeros(len(x), dtype=np.int64)
    hi = np.clip(np.searchsorted(sorted_values, x), 1, len(sorted_values) - 1)
    lo = hi - 1
    return np.where(x - sorted_values[lo] <= sorted_values[hi] - x, lo, hi)


def drive_route(
    truth,
    grid: Grid,
    stops,
    *,
    step_cells: float,
    clearance_cells: float = 2,
) -> np.ndarray:
    r"""Poses along the shortest paths between consecutive ``stops``, ``step_cells`` of path length apart:
    a robot that scans while it drives the route :func:`plan_route` plans.

    The path between two stops is the geodesically shortest 8-connected path (a diagonal step costs
    :math:`\sqrt 2`, no corner cutting) through the cells whose centres lie more than ``clearance_cells``
    from every occupied cell and from the grid edge; poses are placed at the path cells nearest the arc
    lengths ``0, s, 2 s, ...`` of the whole path (the polyline through its cells' centres; each cell once, and
    its last cell), each facing the direction of travel there (the chord to the path cell nearest ``s / 2``
    ahead, at least the next cell; the last pose keeps its predecessor's yaw, a path of one cell faces yaw 0).

    Args:
        truth: ground-truth map, ``rows x cols`` bool (True = occupied), of ``grid.shape``.
        grid: a 2D :class:`~ogm_ppl.grid.Grid`.
        stops: ``P x 2`` or ``P x 3`` poses in metres (a yaw is ignored), each in a cell with clearance.
        step_cells: path length between poses, in cells (> 0).
        clearance_cells: as :func:`plan_route`'s (the default is the same).

    Returns:
        ``Q x 3`` poses ``(x, y, yaw)`` in metres and radians, at cell centres; ``Q >= 1``.

    Raises:
        ValueError: a stop outside the grid, without clearance, or unreachable from the one before it; a
            bad argument.

    >>> from ogm_ppl import Grid
    >>> t = np.zeros((20, 20), bool); t[[0, -1], :] = t[:, [0, -1]] = True
    >>> g = Grid((20, 20), 1.0)
    >>> p = drive_route(t, g, [[4.5, 4.5], [14.5, 4.5]], step_cells=2.5)
    >>> p[:, 0].tolist(), bool(np.allclose(p[:, 2], 0.0))
    ([4.5, 6.5, 9.5, 11.5, 14.5], True)
    """
    truth = _check_truth(truth, grid)
    step_cells = _check_positive("step_cells", step_cells)
    clearance_cells = _check_clearance(clearance_cells)
    stops = np.atleast_2d(np.asarray(stops, dtype=float))
    if stops.ndim != 2 or stops.shape[1] not in (2, 3) or stops.shape[0] < 1:
        raise ValueError(f"stops must have shape P x 2 or P x 3, got {np.shape(stops)}")
    if not np.all(np.isfinite(stops)):
        raise ValueError("stops hold a non-finite value")
    if not grid.contains(stops[:, :2]).all():
        raise ValueError(f"stop {int(np.flatnonzero(~grid.contains(stops[:, :2]))[0])} lies outside the grid")
    valid = _clear_cells(truth, clearance_cells)
    cells = grid.world_to_cell(stops[:, :2])
    bad = ~valid[cells[:, 0], cells[:, 1]]
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise ValueError(f"stop {i} lies within clearance_cells = {clearance_cells} of a wall")
    graph = _KnownFreeGraph(valid)
    graph.update(valid.ravel())
    nodes = graph.node[cells[:, 0] * grid.cols + cells[:, 1]]
    path = [int(nodes[0])]
    for i in range(1, len(nodes)):
        a, b = int(nodes[i - 1]), int(nodes[i])
        if a == b:
            continue
        # Dijkstra settles every cell within ``limit`` exactly; search the whole graph only when b lies further
        limit = 2.0 * float(np.hypot(*(cells[i] - cells[i - 1]))) + 50.0
        d, pred = csgraph.dijkstra(graph.graph, indices=a, return_predecessors=True, limit=limit)
        if not d[b] < np.inf:
            d, pred = csgraph.dijkstra(graph.graph, indices=a, return_predecessors=True)
        if not d[b] < _BIG / 2:
            raise ValueError(f"stop {i} cannot be reached from stop {i - 1} through cells with clearance")
        seg = [b]
        while seg[-1] != a:
            seg.append(int(pred[seg[-1]]))
        path += seg[-2::-1]
    flat = graph.cell[np.asarray(path)]
    xy = grid.cell_to_world(np.stack([flat // grid.cols, flat % grid.cols], axis=1))
    seg_len = np.hypot(*np.diff(xy, axis=0).T) / grid.resolution
    arc = np.concatenate([[0.0], np.cumsum(seg_len)])
    at = np.arange(0.0, arc[-1] + 1e-9, step_cells)
    if arc[-1] - at[-1] > 1e-9:
        at = np.append(at, arc[-1])
    idx = _nearest(arc, at)
    idx = idx[np.concatenate([[True], np.diff(idx) > 0])]  # a path cell once, however short the step
    last = len(arc) - 1
    ahead = np.maximum(_nearest(arc, np.minimum(arc[idx] + step_cells / 2, arc[-1])), np.minimum(idx + 1, last))
    d = xy[ahead] - xy[idx]
    yaw = np.arctan2(d[:, 1], d[:, 0])
    if len(yaw) > 1 and idx[-1] == last:  # nothing lies ahead of the path's last cell
        yaw[-1] = yaw[-2]
    return np.column_stack([xy[idx], yaw])


# --------------------------------------------------------------------------- dataset
def _subset(n: int, fraction: float) -> np.ndarray:
    k = max(1, round(fraction * n))
    return np.unique(np.round(np.linspace(0, n - 1, k)).astype(np.int64))


def stop_and_scan(
    truth,
    grid: Grid,
    *,
    num_poses: int | None = None,
    beams: int = 720,
    max_range_cells: float = 75,
    sigma_cells: float = 3.0,
    seed: int = 0,
    pose_fraction: float = 1.0,
    beam_step: int = 1,
    route=None,
) -> StopAndScan:
    r"""A simulated stop-and-scan dataset of ``truth`` (Section 6.1's setting by default).

    Args:
        truth, grid: the ground-truth map (``rows x cols`` bool, True = occupied) and its 2D grid.
        num_poses: the most stops of the planned route (see :func:`plan_route`).
        beams: beams per full scan, evenly spaced over 360 degrees (720 = 0.5 degree steps).
        max_range_cells: the sensor's maximum range ``F`` in cells (``F * grid.resolution`` metres).
        sigma_cells: standard deviation of the Gaussian range noise in cells (>= 0).
        seed: seeds the route (when planned here) and the noise; the dataset is a function of it.
        pose_fraction: scan at an evenly spaced subset of ``round(pose_fraction * P)`` stops (first and
            last kept), in ``(0, 1]``.
        beam_step: keep every ``beam_step``-th beam (angles ``beam_step * 360 / beams`` degrees apart).
        route: a ``P x 3`` route to use instead of planning one.

    >>> from ogm_ppl import Grid
    >>> t = np.zeros((40, 40), bool); t[[0, -1], :] = t[:, [0, -1]] = True
    >>> d = stop_and_scan(t, Grid((40, 40), 0.1), route=[[2.0, 2.0, 0.0], [1.0, 3.0, 0.0]], beam_step=4)
    >>> d.scans.ranges.shape, d.settings["max_range"]
    ((2, 180), 7.5)
    """
    truth = _check_truth(truth, grid)
    max_range_cells = _check_positive("max_range_cells", max_range_cells)
    sigma_cells = float(sigma_cells)
    if not np.isfinite(sigma_cells) or sigma_cells < 0:
        raise ValueError(f"sigma_cells must be a finite number >= 0, got {sigma_cells!r}")
    if int(beams) != beams or beams < 1:
        raise ValueError(f"beams must be a positive integer, got {beams!r}")
    if int(beam_step) != beam_step or not 1 <= beam_step <= beams:
        raise ValueError(f"beam_step must be an integer in [1, beams = {beams}], got {beam_step!r}")
    pose_fraction = float(pose_fraction)
    if not 0 < pose_fraction <= 1:
        raise ValueError(f"pose_fraction must lie in (0, 1], got {pose_fraction!r}")
    beams, beam_step = int(beams), int(beam_step)
    if route is None:
        route = plan_route(
            truth,
            grid,
            num_poses=num_poses,
            max_range_cells=max_range_cells,
            seed=seed,
        )
        planned = True
    else:
        route = np.atleast_2d(np.asarray(route, dtype=float))
        if route.ndim != 2 or route.shape[1] != 3 or route.shape[0] < 1:
            raise ValueError(f"route must have shape P x 3 (x, y, yaw), got {np.shape(route)}")
        if not np.all(np.isfinite(route)):
            raise ValueError("route has a non-finite value")
        if not grid.contains(route[:, :2]).all():
            raise ValueError("route has a pose outside the grid")
        cells = grid.world_to_cell(route[:, :2])
        hit = truth[cells[:, 0], cells[:, 1]]
        if hit.any():
            raise ValueError(f"route pose {int(np.flatnonzero(hit)[0])} lies in an occupied cell")
        planned = False
    route = np.array(route, dtype=float)
    route.setflags(write=False)
    P = route.shape[0]
    keep = _subset(P, pose_fraction)
    angles = np.arange(beams) * (2 * np.pi / beams)
    max_range = max_range_cells * grid.resolution
    # one noise stream per stop of the full route, all beams drawn: sparser variants are exact subsets
    streams = np.random.SeedSequence(seed).spawn(P)
    ranges = np.empty((keep.size, beams))
    for j, i in enumerate(keep):
        s = simulate_scans(
            grid,
            truth,
            route[i : i + 1],
            angles,
            max_range,
            sigma_cells,
            np.random.default_rng(streams[i]),
        )
        ranges[j] = s.ranges[0]
    b = np.arange(0, beams, beam_step)
    scans = Scans(route[keep], angles[b], ranges[:, b], max_range)
    settings = {
        "beams": beams,
        "beam_step": beam_step,
        "max_range_cells": max_range_cells,
        "max_range": max_range,
        "sigma_cells": sigma_cells,
        "seed": int(seed) if np.ndim(seed) == 0 else seed,
        "num_poses": num_poses,
        "pose_fraction": pose_fraction,
        "route_planned": planned,
        "pose_indices": keep.tolist(),
        "beam_indices": b.tolist(),
    }
    return StopAndScan(scans=scans, route=route, truth=truth, grid=grid, settings=settings)
