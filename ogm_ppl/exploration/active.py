r"""Active mapping in simulation: a stop-and-scan robot that chooses its next stop on its current map.

The loop (:func:`explore`), from a start pose on a ground-truth plan:

1. scan: a 360 degree scan of ``beams`` beams simulated on the truth with the library's own sensor model
   (:func:`~ogm_ppl.datasets.simulate.simulate_scans`, Gaussian range noise of ``sigma_cells``: simulator =
   model), added to the robot's map (a *mapper*, below) and to a traditional occupancy grid that every method
   keeps (what the robot has observed, for coverage and frontiers);
2. score the map against the truth (:func:`stop_metrics`);
3. candidates: the cells of a ``stride`` lattice and the frontier cells that the robot can reach along a path
   with :math:`P(\text{path free} \mid z) \ge` ``threshold`` on its current map
   (:class:`~ogm_ppl.exploration.candidates.PathPlanner`: exact over the posterior samples where the map has
   them, under cell independence otherwise);
4. choose the next stop by the method's rule, drive there along the path, repeat.

Rules (:class:`Method`):

``frontier``
    (a) the geodesically nearest reachable goal cell within ``clearance_cells + 1`` cells (Chebyshev) of a
    frontier cell (a known-free cell next to an unobserved one) on traditional OGM; frontier clusters of fewer
    than ``min_cluster`` cells are ignored and frontier cells near an earlier stop given up (its scan did not
    resolve them): the simulator's rule in :mod:`ogm_ppl.datasets.stop_and_scan` without its look-ahead at
    the truth.
``ogm_info``
    (b) the largest independent-cell information gain
    :math:`\sum_b I(m; z_b)` of the candidate's beams on the marginals of traditional OGM
    (``information.independent_information``, FSMI/FCMI-style).
``sample_info``
    (c, d) the largest information gain from ``samples`` posterior maps of a Gibbs chain under ``prior``
    (``"independent"`` for (c), a learned prior such as ``"patch3:houseexpo"`` for (d)):
    :math:`\sum_b I(m; z_b \mid z)` exactly per beam over the samples' empirical posterior
    (``information.beam_information``; ``estimator = "scan"``: the whole-scan nested Monte-Carlo estimate
    ``information.scan_information``).
``sample_coverage``
    (e) the largest expected number of not-yet-observed free cells the candidate's scan would observe, over the
    same ``samples`` posterior maps under ``prior`` (``information.expected_new_cells``: each of the scan's
    ``beams`` beams ray-cast in each sample up to its first occupied cell, the unobserved cells crossed counted
    once per sample, averaged): the coverage score of MapEx (ICRA 2025), which ray-casts candidates in
    predicted maps, with posterior samples for the predictions. Information gain rewards making the map
    certain, which a learned prior has largely done for unobserved space it predicts well; this rule rewards
    what coverage counts.

Each rule's score may be divided by the metres driven (``per_metre``): :math:`\text{gain} / (d + d_0)` with
:math:`d_0` = ``distance_offset`` metres (default: the sensor's maximum range), as ``stop_and_scan`` weighs
its goals; the frontier rule is nearest-first and has no such variant.

Mappers (:class:`Mapper`, the protocol the loop uses: ``add_scans``, ``samples``, ``marginals``):
:class:`OGMMapper` (traditional OGM, incremental), :class:`RebuildMapper` (the model rebuilt from all scans
at every stop and the chain continued from its last state: the reference) and, where present,
:class:`ogm_ppl.inference.online.OnlineMap` (the model and chain grown in place).
"""

from __future__ import annotations

import importlib
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from typing import Any, Protocol

import numpy as np
import torch
from scipy import ndimage

from ogm_ppl.datasets.simulate import simulate_scans
from ogm_ppl.exploration.candidates import CandidateError, Candidates, PathPlanner, frontier_mask
from ogm_ppl.grid import Grid
from ogm_ppl.scans import Scans

__all__ = [
    "RULES",
    "Choice",
    "ExplorationRun",
    "Mapper",
    "Method",
    "OGMMapper",
    "OnlineMapper",
    "RebuildMapper",
    "Robot",
    "choose_start",
    "default_mapper",
    "kernel_for",
    "explore",
    "path_to",
    "stop_metrics",
]

RULES = ("frontier", "ogm_info", "sample_info", "sample_coverage")
SAMPLE_RULES = ("sample_info", "sample_coverage")  # rules that draw posterior samples under a prior


# ------------------------------------------------------------------------------------------ settings
@dataclass(frozen=True)
class Robot:
    r"""Sensor, motion and map settings of a run (cells are grid cells).

    Attributes:
        beams: beams per 360 degree scan. info_beams: beams of a candidate scan scored for information gain
            (evenly spaced; 0: ``beams``).
        max_range_cells, sigma_cells: the sensor's range and Gaussian range noise.
        clearance_cells: radius of the robot's disk (paths must keep it free).
        threshold: least ``P(path free)`` of a candidate's path.
        stride: lattice spacing of the candidate cells. risk_weight: the planner's cells per nat of risk.
        min_step_cells: least distance (cells) of a candidate from the robot; a frontier cell this close to
            an earlier stop is given up.
        min_cluster: frontier clusters (8-connected) of fewer cells are ignored (a gap the robot does not fit).
        max_candidates: information rules score at most this many candidates per stop (a seeded uniform
            subset of the gated ones).
        samples: posterior maps per stop (rules ``sample_info``, ``sample_coverage``; also the P(path free) of
            their paths).
        sweeps: chain sweeps after each new scan before sampling; thin: sweeps between samples.
        delta: the update term of the traditional OGM every run keeps.
        ogm_gate: how rules on traditional OGM gate paths: ``"threshold"`` (default) on the thresholded map
            (observed cells with ``p < 0.5`` free, all others occupied: ``P(path free)`` is 0 or 1, the
            planner's conventional use of an evidence grid), or ``"product"``, the independent product
            :math:`\prod (1 - p_c)` of its marginals (with the Haehnel update a cell one beam crossed holds
            ``p = 0.2``, so any path past a few such cells falls below a 0.9 gate).
        max_path_length: end the run at the first stop reached after driving this many metres (a budget
            that compares rules at equal path length whatever their step sizes).
    """

    beams: int = 90
    info_beams: int = 0
    max_range_cells: float = 20.0
    sigma_cells: float = 1.0
    clearance_cells: float = 1.0
    threshold: float = 0.9
    stride: int = 4
    risk_weight: float = 4.0
    min_step_cells: float = 2.0
    min_cluster: int = 5
    max_candidates: int = 400
    samples: int = 32
    sweeps: int = 10
    thin: int = 1
    delta: str = "haehnel"
    ogm_gate: str = "threshold"
    max_path_length: float = float("inf")

    def __post_init__(self) -> None:
        for k in ("beams", "stride", "samples", "thin", "min_cluster", "max_candidates"):
            v = getattr(self, k)
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 1:
                raise ValueError(f"Robot.{k} must be a positive integer, got {v!r}")
        for k in ("info_beams", "sweeps"):
            v = getattr(self, k)
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 0:
                raise ValueError(f"Robot.{k} must be an integer >= 0, got {v!r}")
        for k in ("max_range_cells", "sigma_cells"):
            v = float(getattr(self, k))
            if not (np.isfinite(v) and v > 0):
                raise ValueError(f"Robot.{k} must be a positive finite number, got {v!r}")
        for k in ("clearance_cells", "risk_weight", "min_step_cells"):
            v = float(getattr(self, k))
            if not (np.isfinite(v) and v >= 0):
                raise ValueError(f"Robot.{k} must be a finite number >= 0, got {v!r}")
        if not float(self.max_path_length) > 0:
            raise ValueError(f"Robot.max_path_length must be > 0 metres, got {self.max_path_length!r}")
        if self.ogm_gate not in ("threshold", "product"):
            raise ValueError(f"Robot.ogm_gate must be 'threshold' or 'product', got {self.ogm_gate!r}")
        if not 0 < self.threshold <= 1:
            raise ValueError(f"Robot.threshold must lie in (0, 1], got {self.threshold!r}")


@dataclass(frozen=True)
class Method:
    """How the next stop is chosen (module docstring).

    Attributes:
        name: a label. rule: one of :data:`RULES`. prior: the prior name of rules ``sample_info`` and
            ``sample_coverage`` (:func:`~ogm_ppl.priors.named.prior_by_name`). per_metre: divide the gain by
            ``d + d_0``.
        distance_offset: ``d_0`` in metres (None: the sensor's maximum range).
        estimator: ``"beam"`` (exact per-beam MI, summed) or ``"scan"`` (whole-scan nested Monte Carlo).
        scan_draws: draws of the ``"scan"`` estimator. patch: the Gibbs patch (None: the prior's tile when its
            bundle weighs a sparse support, else single cells).
    """

    name: str
    rule: str
    prior: str | None = None
    per_metre: bool = False
    distance_offset: float | None = None
    estimator: str = "beam"
    scan_draws: int = 64
    patch: tuple[int, int] | None = None

    def __post_init__(self) -> None:
        if self.rule not in RULES:
            raise ValueError(f"Method.rule must be one of {', '.join(RULES)}, got {self.rule!r}")
        if (self.rule in SAMPLE_RULES) != (self.prior is not None):
            raise ValueError(
                f"Method {self.name!r}: a prior is given with rule 'sample_info' or 'sample_coverage' and only "
                "with them"
            )
        if self.rule == "frontier" and self.per_metre:
            raise ValueError(f"Method {self.name!r}: the frontier rule is nearest-first; per_metre does not apply")
        if self.estimator not in ("beam", "scan"):
            raise ValueError(f"Method.estimator must be 'beam' or 'scan', got {self.estimator!r}")
        if self.distance_offset is not None and not (np.isfinite(self.distance_offset) and self.distance_offset > 0):
            raise ValueError(f"Method.distance_offset must be a positive number, got {self.distance_offset!r}")


# ------------------------------------------------------------------------------------------ mappers
class Mapper(Protocol):
    """What the exploration loop needs of a map: scans in, posterior samples and marginals out."""

    def add_scans(self, scans: Scans) -> None: ...

    def samples(self, num_samples: int) -> torch.Tensor: ...

    @property
    def marginals(self) -> torch.Tensor: ...


class OGMMapper:
    """Traditional OGM (Eq. 2.10), updated in place: the log-odds of new scans add to the old ones
    (:func:`~ogm_ppl.inference.evidence_grid_from_scans` per batch; no clamp, so the sum is exact).

    ``observed``: cells that some update touched. ``samples`` draws independent cells from the marginals."""

    def __init__(self, grid: Grid, delta: str = "haehnel", prior: float = 0.5, seed: int = 0) -> None:
        from ogm_ppl.models import delta_by_name

        self.grid = grid
        self.delta = delta_by_name(delta)
        self.prior = float(prior)
        self._l0 = float(np.log(prior / (1 - prior)))
        self.log_odds = np.full(grid.num_cells, self._l0)
        self.observed = np.zeros(grid.num_cells, dtype=bool)
        self._rng = torch.Generator().manual_seed(int(seed))

    def add_scans(self, scans: Scans) -> None:
        from ogm_ppl.inference import evidence_grid_from_scans

        ev = evidence_grid_from_scans(self.grid, scans, self.delta, prior=self.prior)
        self.log_odds += ev.log_odds.numpy() - self._l0
        self.observed |= ev.observed.numpy()

    @property
    def marginals(self) -> torch.Tensor:
        return torch.sigmoid(torch.from_numpy(self.log_odds))

    def samples(self, num_samples: int) -> torch.Tensor:
        p = self.marginals
        return (torch.rand((int(num_samples), p.numel()), generator=self._rng, dtype=torch.float64) < p).to(torch.uint8)


def kernel_for(model, patch=None, init="ogm"):
    """The Gibbs kernel of ``model``: :class:`~ogm_ppl.inference.PatchGibbs` over ``patch``, or (None) over the
    prior's tile when its compiled bundle weighs a sparse support (a tile table, where single-cell moves stick),
    else :class:`~ogm_ppl.inference.CellGibbs`."""
    from ogm_ppl.inference import CellGibbs, PatchGibbs

    if patch is None:
        c = model.prior.compiled()
        if c is not None and c.sparse_patches():
            hw = (int(getattr(c, "t_h", 3)), int(getattr(c, "t_w", 3)))
            patch = None if hw == (1, 1) else hw
    return CellGibbs(model, init=init) if patch is None else PatchGibbs(model, tuple(patch), init=init)


class RebuildMapper:
    """A Gibbs chain on the model of all scans so far, rebuilt from scratch at every :meth:`add_scans`: the ray
    cast, the model (:class:`~ogm_ppl.OccupancyModel`) and the kernel are made anew and the chain continues
    from its last map (traditional OGM thresholded at the prior's mean before the first scan), then runs
    ``sweeps`` sweeps. The reference for an online map, which grows the same model in place.

    ``marginals``: the running mean of the states sampled since the last :meth:`add_scans` (the state after
    the sweeps if none). Uses torch's global generator (seed it for a reproducible run).
    """

    def __init__(self, grid: Grid, sensor, prior, *, sweeps: int = 10, thin: int = 1, patch=None) -> None:
        self.grid, self.sensor, self.prior = grid, sensor, prior
        self.sweeps, self.thin, self.patch = int(sweeps), int(thin), patch
        self._scans: list[Scans] = []
        self.kernel: Any = None
        self._sum = np.zeros(grid.num_cells)
        self._n = 0

    @property
    def scans(self) -> Scans:
        """All scans so far, as one :class:`~ogm_ppl.scans.Scans`."""
        s = self._scans
        return Scans(
            np.concatenate([x.poses for x in s]),
            s[0].angles if s[0].angles.ndim == 1 else np.concatenate([x.angles for x in s]),
            np.concatenate([x.ranges for x in s]),
            s[0].max_range,
        )

    def add_scans(self, scans: Scans) -> None:
        from ogm_ppl.models import OccupancyModel
        from ogm_ppl.raycast import raycast

        first = self._scans[0] if self._scans else scans
        if scans.max_range != first.max_range or scans.angles.shape != first.angles.shape:
            raise ValueError("scans added with another maximum range or beam layout than the first ones")
        self._scans.append(scans)
        model = OccupancyModel(self.grid, raycast(self.grid, self.scans), self.sensor, self.prior)
        init = "ogm" if self.kernel is None else torch.from_numpy(self.kernel.state.astype(np.float64))
        self.kernel = kernel_for(model, self.patch, init)
        self.kernel.setup(0)
        self._params = self.kernel.current_params()
        self._sweep(self.sweeps)
        self._sum[:] = 0.0
        self._n = 0

    def _sweep(self, n: int) -> None:
        for _ in range(n):
            self._params = self.kernel.sample(self._params)

    def samples(self, num_samples: int) -> torch.Tensor:
        if self.kernel is None:
            raise RuntimeError("RebuildMapper has no scans yet: add_scans first")
        out = np.empty((int(num_samples), self.grid.num_cells), dtype=np.uint8)
        for i in range(int(num_samples)):
            self._sweep(self.thin)
            out[i] = self.kernel.state
        self._sum += out.sum(0)
        self._n += out.shape[0]
        return torch.from_numpy(out)

    @property
    def marginals(self) -> torch.Tensor:
        if self.kernel is None:
            raise RuntimeError("RebuildMapper has no scans yet: add_scans first")
        if self._n == 0:
            return torch.from_numpy(self.kernel.state.astype(np.float64))
        return torch.from_numpy(self._sum / self._n)


class OnlineMapper:
    """The :class:`Mapper` face of an :class:`~ogm_ppl.inference.online.OnlineMap` (the model and the chain
    grown in place, no rebuild): ``add_scans`` adds the scans and runs ``sweeps`` sweeps by its schedule,
    then restarts the running mean, so :attr:`marginals` is the mean of the states :meth:`samples` returned
    (as for :class:`RebuildMapper`)."""

    def __init__(self, online_map, sweeps: int, thin: int = 1) -> None:
        self.map, self.sweeps, self.thin = online_map, int(sweeps), int(thin)

    def add_scans(self, scans: Scans) -> None:
        self.map.add_scans(scans, self.sweeps)
        self.map.reset_marginals()

    def samples(self, num_samples: int) -> torch.Tensor:
        return self.map.samples(int(num_samples), self.thin)

    @property
    def marginals(self) -> torch.Tensor:
        return self.map.marginals


def default_mapper(grid: Grid, sensor, prior, robot: Robot, seed: int, patch=None) -> Mapper:
    """The mapper of rules ``sample_info`` and ``sample_coverage``: the online map (:class:`OnlineMapper`,
    single-cell Gibbs) where :func:`kernel_for` would pick single cells and :mod:`ogm_ppl.inference.online` is
    there, else :class:`RebuildMapper` (patch Gibbs: tile-table priors, whose single-cell moves stick)."""
    c = prior.compiled()
    cells = patch is None and not (c is not None and c.sparse_patches())
    if cells:
        try:
            online = importlib.import_module("ogm_ppl.inference.online")
        except ImportError:
            online = None
        if online is not None:
            return OnlineMapper(online.OnlineMap(grid, sensor, prior, seed=int(seed) % 2**63), robot.sweeps, robot.thin)
    return RebuildMapper(grid, sensor, prior, sweeps=robot.sweeps, thin=robot.thin, patch=patch)


# ------------------------------------------------------------------------------------------ metrics
def stop_metrics(q, truth: np.ndarray, observed: np.ndarray, target: np.ndarray, mask: np.ndarray) -> dict:
    """Scores of a map after a stop: ``coverage`` (share of the ``target`` free cells observed), ``f1`` (best
    F1 of the marginals ``q`` over the thresholds 0.01..0.99 on ``mask``) and ``nll_bits`` (bits per cell on
    ``mask``)."""
    from ogm_ppl.metrics import best_f1, nll_bits

    qn = np.asarray(q, dtype=float)
    f1, thr = best_f1(qn, truth, mask=mask)
    return {
        "coverage": float((observed & target).sum() / max(1, target.sum())),
        "f1": float(f1),
        "f1_threshold": float(thr),
        "nll_bits": float(nll_bits(qn, truth, mask)),
    }


def path_to(records: list[dict], key: str, level: float) -> float:
    """The path length (metres) after which ``records[i][key] >= level`` first holds (inf if never)."""
    for r in records:
        if r[key] >= level:
            return float(r["path_length"])
    return float("inf")


# ------------------------------------------------------------------------------------------ the loop
@dataclass
class ExplorationRun:
    """One run of :func:`explore`.

    Attributes:
        records: one dict per stop (stop, path_length m, coverage, f1, nll_bits, f1_ogm, nll_ogm, candidates,
            score, p_free, collisions, seconds since the start).
        route: ``P x 3`` stops (metres, radians). stopped: why the run ended.
        maps: the robot's marginals after the last stop (``K``). settings: what was run.
    """

    records: list[dict]
    route: np.ndarray
    stopped: str
    maps: np.ndarray
    settings: dict = field(default_factory=dict)

    def path_to(self, key: str, level: float) -> float:
        return path_to(self.records, key, level)


@dataclass(frozen=True)
class Choice:
    """What a rule chose from at a stop of :func:`explore` (its ``on_choice`` hook): the ``chosen`` index of
    ``candidates`` (None: none worth driving to), the posterior ``samples`` (sample rules, else None), the cells
    ``observed`` so far, and what the rule scored with (the ``sensor``, the beams ``info_angles`` scored for
    information, the scan's beams ``scan_angles``, ``max_range`` in metres, the distance offset ``d0``)."""

    stop: int
    chosen: int | None
    candidates: Candidates
    samples: Any
    observed: np.ndarray
    sensor: Any
    info_angles: np.ndarray
    scan_angles: np.ndarray
    max_range: float
    d0: float


def choose_start(truth: np.ndarray, clearance_cells: float, seed: int) -> tuple[int, int]:
    """A seeded random cell of the largest 8-connected region of cells farther than ``clearance_cells`` from
    every occupied cell and the grid edge (``plan_route``'s default start)."""
    free = ~np.asarray(truth, dtype=bool)
    clear = ndimage.distance_transform_edt(np.pad(free, 1))[1:-1, 1:-1]
    valid = clear > clearance_cells
    if not valid.any():
        raise ValueError(f"no free cell keeps clearance_cells = {clearance_cells} from the walls and the grid edge")
    lab, _ = ndimage.label(valid, structure=np.ones((3, 3), bool))
    sizes = np.bincount(lab.ravel())
    sizes[0] = 0
    cells = np.flatnonzero(lab.ravel() == np.argmax(sizes))
    s = int(cells[np.random.default_rng(seed).integers(cells.size)])
    return divmod(s, truth.shape[1])


def _information():
    return importlib.import_module("ogm_ppl.exploration.information")


def explore(
    truth,
    grid: Grid,
    method: Method,
    robot: Robot = Robot(),
    *,
    stops: int = 10,
    seed: int = 0,
    start: tuple[int, int] | None = None,
    stop_coverage: float = 1.0,
    mask=None,
    mapper_factory: Callable | None = None,
    prior=None,
    on_choice: Callable[[Choice], None] | None = None,
) -> ExplorationRun:
    r"""Explore ``truth`` (``rows x cols`` bool, True = occupied) with ``method`` for at most ``stops`` scans.

    Args:
        start: the start cell ``(row, col)``; default :func:`choose_start` with ``seed``.
        stop_coverage: end once this share of the start's free component has been observed.
        mask: cells scored (default all); ``target`` of the coverage: the free cells 4-connected to the start.
        mapper_factory: ``factory(grid, sensor, prior, robot, seed, patch) -> Mapper`` for rule
            ``sample_info`` and ``sample_coverage`` (default :func:`default_mapper`).
        prior: a :class:`~ogm_ppl.priors.MapPrior` to use instead of ``prior_by_name(method.prior)``.
        on_choice: called with the :class:`Choice` of each stop after the rule chose (a probe of the rule).

    The run is a function of ``seed``: the start, the range noise of stop ``i`` (its own stream
    ``SeedSequence(seed).spawn``) and the chain (torch's generator is seeded here and restored afterwards).
    """
    from ogm_ppl.sensors import GaussianRange

    truth = np.asarray(truth, dtype=bool)
    if not isinstance(grid, Grid) or grid.ndim != 2 or truth.shape != grid.shape:
        raise ValueError(f"truth has shape {truth.shape}; it must match a 2D grid (got {grid!r})")
    if int(stops) != stops or stops < 1:
        raise ValueError(f"stops must be a positive integer, got {stops!r}")
    mask = np.ones(grid.num_cells, bool) if mask is None else np.asarray(mask, bool).ravel()
    if start is None:
        start = choose_start(truth, robot.clearance_cells, seed)
    r0, c0 = (int(v) for v in start)
    if not (0 <= r0 < grid.rows and 0 <= c0 < grid.cols):
        raise CandidateError(f"start cell ({r0}, {c0}) lies off the grid {grid.shape}")
    if truth[r0, c0]:
        raise CandidateError(f"start cell ({r0}, {c0}) lies inside an obstacle")
    lab, _ = ndimage.label(~truth)
    target = (lab == lab[r0, c0]).ravel()
    flat_truth = truth.ravel()

    sensor = GaussianRange(robot.sigma_cells)
    res = grid.resolution
    max_range = robot.max_range_cells * res
    angles = np.arange(robot.beams) * (2 * np.pi / robot.beams)
    nb = robot.info_beams or robot.beams
    info_angles = np.arange(nb) * (2 * np.pi / nb)
    streams = np.random.SeedSequence(seed).spawn(int(stops))
    planner = PathPlanner(grid, robot.clearance_cells, robot.risk_weight)
    ogm = OGMMapper(grid, robot.delta, seed=seed)
    d0 = method.distance_offset if method.distance_offset is not None else max_range

    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(int(seed))
        mapper: Mapper = ogm
        if method.rule in SAMPLE_RULES:
            from ogm_ppl.priors.named import prior_by_name

            pr = prior if prior is not None else prior_by_name(str(method.prior), grid.shape)
            make = mapper_factory if mapper_factory is not None else default_mapper
            mapper = make(grid, sensor, pr, robot, seed, method.patch)
        cell = r0 * grid.cols + c0
        route = [np.array([*grid.cell_to_world(np.array([[r0, c0]]))[0], 0.0])]
        stops_done: list[int] = []
        path_length, collisions = 0.0, 0
        records: list[dict] = []
        t0 = time.perf_counter()
        stopped = "stops"
        info = {"candidates": 0, "score": float("nan"), "gain_bits": float("nan"), "p_free": float("nan")}
        if method.rule == "sample_coverage":
            info["gain_cells"] = float("nan")
        for i in range(int(stops)):
            pose = route[-1]
            scan = simulate_scans(
                grid, truth, pose[None], angles, max_range, robot.sigma_cells, np.random.default_rng(streams[i])
            )
            ogm.add_scans(scan)
            if mapper is not ogm:
                mapper.add_scans(scan)
            stops_done.append(cell)
            samples = mapper.samples(robot.samples) if method.rule in SAMPLE_RULES else None
            q = mapper.marginals.numpy()
            q_ogm = ogm.marginals.numpy()
            rec = {"stop": i, "path_length": path_length, "collisions": collisions, **info}
            rec.update(stop_metrics(q, flat_truth, ogm.observed, target, mask))
            og = stop_metrics(q_ogm, flat_truth, ogm.observed, target, mask)
            rec.update({"f1_ogm": og["f1"], "nll_ogm": og["nll_bits"], "seconds": time.perf_counter() - t0})
            records.append(rec)
            if rec["coverage"] >= stop_coverage:
                stopped = "coverage"
                break
            if path_length >= robot.max_path_length:
                stopped = "path length"
                break
            if i == stops - 1:
                break
            goal, cand, info = _choose(
                method, robot, planner, grid, cell, q, q_ogm, samples, ogm.observed, stops_done, sensor,
                info_angles, max_range, d0, np.random.default_rng(streams[i].spawn(1)[0]), scan_angles=angles,
            )  # fmt: skip
            if on_choice is not None:
                on_choice(Choice(i, goal, cand, samples, ogm.observed, sensor, info_angles, angles, max_range, d0))
            if goal is None:
                stopped = "no candidate"
                break
            path = cand.path(goal)
            hit = np.flatnonzero(flat_truth[path])
            if hit.size:  # the robot bumps into a wall its map did not show: it stops before it
                collisions += 1
                path = path[: max(1, int(hit[0]))]
            steps = np.abs(np.diff(path))
            path_length += float(np.where((steps == 1) | (steps == grid.cols), 1.0, np.sqrt(2.0)).sum()) * res
            prev, cell = route[-1], int(path[-1])
            xy = grid.cell_to_world(np.array([divmod(cell, grid.cols)]))[0]
            route.append(np.array([xy[0], xy[1], float(np.arctan2(xy[1] - prev[1], xy[0] - prev[0]))]))
    settings = {"method": asdict(method), "robot": asdict(robot), "stops": int(stops), "seed": int(seed)}
    settings["start"] = [r0, c0]
    return ExplorationRun(records, np.array(route[: len(records)]), stopped, q, settings)


def _choose(
    method, robot, planner, grid, cell, q, q_ogm, samples, observed, stops_done, sensor, angles, max_range, d0,
    rng=None, scan_angles=None,
):  # fmt: skip
    """``(index of the chosen candidate or None, candidates, info)``; ``rng`` draws the subset of candidates
    scored when more than ``robot.max_candidates`` pass the gate. ``angles``: the beams scored for information
    gain; ``scan_angles``: the beams of the scan itself (rule ``sample_coverage``; None: ``angles``)."""
    fr = frontier_mask(grid, q_ogm, observed)  # the goals: cells within reach of a frontier cell
    reach = int(np.ceil(robot.clearance_cells)) + 1  # a goal lies this close (Chebyshev) to its frontier cell
    if method.rule == "frontier" and stops_done:  # frontier cells an earlier stop could not resolve are given up
        done = np.zeros(grid.shape, bool)
        done.ravel()[np.asarray(stops_done)] = True
        near = ndimage.distance_transform_edt(~done) <= reach * np.sqrt(2.0) + robot.min_step_cells
        fr &= ~near.ravel()
    lab, n = ndimage.label(fr.reshape(grid.shape), structure=np.ones((3, 3), bool))
    sizes = np.bincount(lab.ravel(), minlength=n + 1)
    sizes[0] = 0
    fr &= (sizes[lab] >= robot.min_cluster).ravel()
    goals = ndimage.maximum_filter(fr.reshape(grid.shape), size=2 * reach + 1, mode="constant").ravel()
    if method.rule in SAMPLE_RULES:
        route_map = q
    elif robot.ogm_gate == "threshold":
        route_map = np.where(observed & (q_ogm < 0.5), 0.0, 1.0)
    else:
        route_map = q_ogm
    cand: Candidates = planner.candidates(
        cell,
        route_map,
        samples,
        threshold=robot.threshold,
        stride=robot.stride if method.rule != "frontier" else None,
        frontier=goals,
        min_distance_cells=robot.min_step_cells,
    )
    info = {"candidates": len(cand), "score": float("nan"), "gain_bits": float("nan"), "p_free": float("nan")}
    if method.rule == "sample_coverage":
        info["gain_cells"] = float("nan")
    if method.rule == "frontier":
        ok = np.flatnonzero(cand.frontier)
        if ok.size == 0:
            return None, cand, info
        j = int(ok[np.argmin(cand.distance[ok])])
        info.update(score=float(cand.distance[j]), p_free=float(cand.p_free[j]))
        return j, cand, info
    if len(cand) == 0:
        return None, cand, info
    if len(cand) > robot.max_candidates:
        rng = np.random.default_rng(0) if rng is None else rng
        cand = cand.subset(np.sort(rng.choice(len(cand), robot.max_candidates, replace=False)))
    info_mod = _information()
    if method.rule == "sample_coverage":
        rays = info_mod.candidate_rays(grid, cand.poses, angles if scan_angles is None else scan_angles, max_range)
        gain = info_mod.expected_new_cells(grid, samples, rays, observed)
        what, key = "expected new cells", "gain_cells"
    else:
        rays = info_mod.candidate_rays(grid, cand.poses, angles, max_range)
        if method.rule == "ogm_info":
            gain = info_mod.independent_information(grid, sensor, torch.from_numpy(q_ogm), rays).sum(1)
        elif method.estimator == "beam":
            gain = info_mod.beam_information(grid, sensor, samples, rays).sum(1)
        else:
            gain = info_mod.scan_information(grid, sensor, samples, rays, num_draws=method.scan_draws).mean
        what, key = "information gain", "gain_bits"
    gain = np.asarray(gain.detach().numpy() if hasattr(gain, "detach") else gain, dtype=float)
    if not np.isfinite(gain).all():
        raise FloatingPointError(f"{what} of {method.name!r} is not finite")
    score = gain / (cand.distance + d0) if method.per_metre else gain
    j = int(np.argmax(score))
    if gain[j] <= 1e-9:
        return None, cand, info
    info.update({"score": float(score[j]), key: float(gain[j]), "p_free": float(cand.p_free[j])})
    return j, cand, info
