r"""Online correlated mapping: scans added to a model and to a running single-cell Gibbs chain without a
rebuild (the online version asked for in the thesis's future work, Section 7.2: "focusing the map updates
to areas with new measurements"; the sampler is the single-cell Gibbs of Section 4.1, Eq. 4.2).

**What grows, and what it costs.** :meth:`OnlineMap.add_scans` ray-casts only the new scans, computes the
likelihood rows ``log p(z_r | f)`` of the new rays only (the code of
:class:`~ogm_ppl.models.occupancy.OccupancyModel` on the new rays alone: the rows agree with those of a model
built from scratch to within 2 ulp, as torch's vectorised and scalar loops may round the last bit apart),
appends them to a ray index held with spare capacity (:mod:`~ogm_ppl.inference._kernels.online`: rays in
CSR form, a ragged likelihood table of ``nnz + R`` floats, the transposed cell -> (ray, kappa) index in a
pool of per-cell blocks), and updates the chain's state for the new rays only: their first and second hits
``f_r, s_r`` at the current map, and their terms in the kept sums ``d_k`` of the cells they reach. The
ray-side arrays double when full (amortised ``O(1)`` a ray-cell entry); the cell pool doubles and compacts.
**Memory bound:** with ``nnz`` ray-cell entries, ``R`` rays and ``K`` cells, the ray side holds at most
``2 nnz`` cells (int64), ``2 (nnz + R)`` table entries (float64) and ``2 R`` offsets and hit records, and
the cell pool at most ``2 (2 nnz + 4 K)`` (ray, kappa) pairs of int32, so the online arrays take at most
``64 nnz + 64 R + 105 K`` bytes (:meth:`OnlineMap.stats` reports them). The offline model of the same
scans holds its CSR and transposed index (``24 nnz``) and a dense table of ``8 R (max len + 1)`` bytes.

**Fixed-point scale.** The kept sums are integers in units of ``2^-S``
(:mod:`~ogm_ppl.inference._kernels.cell_sweep`). Offline, ``S`` comes from the largest ``|log p|`` and the
most rays through a cell (:func:`~ogm_ppl.inference._kernels.cell_sweep.fixed_point_bits`); online both grow.
``OnlineMap`` keeps *caps* ``n_cap >= max_k n_k`` (starting at ``initial_rays_per_cell``) and ``b_cap >=
max |ll|`` (starting at twice the first scans' largest entry), and uses ``S = min(60, floor(62 -
log2(n_cap (2 b_cap + 1) + 1)))``, the offline rule at the caps, so no sum can overflow while the caps
hold. When new rays exceed a cap it is doubled; if ``S`` then drops, every ``d_k`` is recomputed from the
hits at the new ``S`` (exact, ``O(nnz)``; at most ``log2`` of the growth of the caps times over a run).
The state then equals, bit for bit, the from-scratch state (:func:`~ogm_ppl.inference._kernels.cell_sweep.cell_state`)
of the same map, rays and table at ``bits = OnlineMap.bits``; against the table of a model rebuilt from
scratch the sums were equal too in every test (a last-bit difference of an entry changes its fixed-point
value only if it lies within an ulp of a rounding boundary).

**Focused sweeps and the schedule.** After adding scans, ``sweeps`` (default ``sweeps_per_scan``) sweeps
run; sweep number ``t`` (counted from 1 over the chain's life) is a *full* sweep over every latent cell of
the grid when ``full_every > 0`` and ``t % full_every == 0``, and otherwise a *focused* sweep over the
latent cells of the focus region: the cells where the rays of the latest ``add_scans`` end (their
readings' cells in the grid) and the new rays' current first and second hits (an occupied cell in front of
a reading is what the reading contradicts; for a ray without a hit, its last cell), dilated by ``margin``
cells (Chebyshev). The free cells along the new rays between the sensor and the reading get strong
free evidence and are left to the full sweeps. Every cell is thus visited at least once every
``full_every`` sweeps. Each sweep is a systematic pass of heat-bath (or metropolised)
single-cell updates of the posterior given *all* scans so far, so each leaves that posterior invariant
(a focused sweep is the ``region=`` kernel of :class:`~ogm_ppl.inference.mcmc.CellGibbs` on the focus
cells); the full sweeps make the chain irreducible over the whole map. Cells whose pose the new scans
hold become pinned free (as ``known_free="sensor"`` of the offline model) and are set to 0 with the state
kept in step.

Random numbers: sweep ``t`` draws its uniforms from the SplitMix64 stream seeded by a hash of ``(seed,
t)`` (:func:`~ogm_ppl.inference._kernels.cell_sweep.draws`), so a chain is reproducible from its seed.
Priors: any prior with a compiled face (``prior.compiled()``: independent cells, MRF / stencil priors,
pattern fields), through the compiled single-cell sweep. A tile-table prior is accepted with a
:class:`TilePriorWarning`: single-cell moves under it are exact but leave the chain all but frozen, and such
priors are mapped with patch Gibbs instead (:class:`~ogm_ppl.exploration.active.RebuildMapper`).
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass

import numpy as np
import torch

from ogm_ppl.grid import Grid
from ogm_ppl.inference._kernels import cell_sweep as cs
from ogm_ppl.inference._kernels import online as ok
from ogm_ppl.inference.log_odds.maps import add_evidence
from ogm_ppl.inference.mcmc.kernel import ogm_start_threshold
from ogm_ppl.models.delta import Moravec
from ogm_ppl.models.occupancy import OccupancyModel, check_prior_fits
from ogm_ppl.raycast import Rays, raycast
from ogm_ppl.scans import Scans
from ogm_ppl.sensors import SensorModel

__all__ = ["OnlineMap", "OnlineStats", "Replay", "TilePriorWarning", "replay"]

_UPDATES = {"gibbs": cs.HEAT_BATH, "metropolised": cs.METROPOLISED}
_MIX = 0x9E3779B97F4A7C15
_HAEHNEL = Moravec.haehnel()  # the update term of the thresholded-OGM start (initial_map's default)


class TilePriorWarning(UserWarning):
    """A tile-table prior (a compiled bundle with ``sparse_patches()``) given to :class:`OnlineMap`, whose
    single-cell updates leave such a chain all but frozen."""


@dataclass(frozen=True)
class OnlineStats:
    """Sizes of an :class:`OnlineMap`: live counts and allocated capacities (entries, not bytes)."""

    scans: int
    rays: int
    nnz: int
    ray_capacity: int
    entry_capacity: int
    pool_used: int
    pool_capacity: int
    bits: int
    rescales: int
    nbytes: int


def _same_sensor(a: SensorModel, b: SensorModel) -> bool:
    if a is b:
        return True
    if type(a) is not type(b):
        return False
    va, vb = vars(a), vars(b)
    if va.keys() != vb.keys():
        return False
    for k in va:
        x, y = va[k], vb[k]
        if isinstance(x, (torch.Tensor, np.ndarray)) or isinstance(y, (torch.Tensor, np.ndarray)):
            if not torch.equal(torch.as_tensor(x), torch.as_tensor(y)):
                return False
        elif x != y:
            return False
    return True


def _grow(a: np.ndarray, n: int) -> np.ndarray:
    """``a`` with room for at least ``n`` items along axis 0 (capacity doubled; the new room is not
    initialised: only the live part is ever read)."""
    if a.shape[0] >= n:
        return a
    cap = max(n, 2 * a.shape[0], 16)
    out = np.empty((cap,) + a.shape[1:], a.dtype)
    out[: a.shape[0]] = a
    return out


def _bits_for(n_cap: int, b_cap: float) -> int:
    bound = n_cap * (2.0 * b_cap + 1.0) + 1.0
    return min(60, math.floor(62 - math.log2(bound)))


class OnlineMap:
    """An online single-cell Gibbs chain over the map given every scan added so far (module docstring).

    Args:
        grid: the grid (``K`` cells); every scan's poses must lie in it.
        sensor: the sensor model of every scan.
        prior: a :class:`~ogm_ppl.priors.MapPrior` over ``K`` cells with a compiled face (``prior.compiled()``).
        kernel: ``"cell"`` (single-cell updates; the only kind).
        update: ``"gibbs"`` (heat bath, Eq. 4.2) or ``"metropolised"``.
        seed: seeds every sweep's random stream.
        sweeps_per_scan: sweeps :meth:`add_scans` runs by default after adding scans.
        full_every: every ``full_every``-th sweep is a full sweep (0: never; then cells outside the focus
            regions are not visited).
        margin: cells added around the new rays' cells to form the focus region.
        init: the starting map: ``"free"`` or a ``K`` 0/1 map.
        init_new: ``"keep"`` (default: cells keep their state when rays first reach them) or ``"hits"``: a
            latent cell that the new rays are the first to reach starts occupied if one of them ends in it and
            free otherwise (the inverse sensor model, like the thresholded-OGM start of the offline chains).
            That is a restart of those cells, not a move of the chain: the chain then converges again from
            there (the cells had no readings before, so only prior draws are lost). ``"ogm"``: every latent
            cell the new rays reach restarts from traditional OGM over *all* scans so far, thresholded as the
            offline chains' start (:func:`~ogm_ppl.inference.mcmc.kernel.initial_map`: Haehnel's Delta,
            threshold the prior's mean occupancy); the map keeps that evidence grid, ``l_k = sum_r
            Delta(d_{r,k})``, incrementally (:attr:`evidence`, ``K`` float64). Also a restart, of cells that
            may have readings: the chain's state there is replaced by the OGM estimate (each ``add_scans``
            changes the target anyway), so the focused sweeps start every new target where an offline chain
            would start it.
        initial_rays_per_cell: the first cap ``n_cap`` of the fixed-point scale (module docstring).

    Attributes:
        sweeps_done: sweeps run so far; ``full_sweeps``: how many of them were full.
    """

    def __init__(
        self,
        grid: Grid,
        sensor: SensorModel,
        prior,
        *,
        kernel: str = "cell",
        update: str = "gibbs",
        seed: int = 0,
        sweeps_per_scan: int = 2,
        full_every: int = 10,
        margin: int = 2,
        init="free",
        init_new: str = "keep",
        initial_rays_per_cell: int = 256,
    ) -> None:
        if kernel != "cell":
            raise ValueError(f"OnlineMap supports kernel='cell' (single-cell updates), got {kernel!r}")
        if update not in _UPDATES:
            raise ValueError(f"update must be one of {tuple(_UPDATES)}, got {update!r}")
        if not isinstance(grid, Grid):
            raise TypeError(f"grid must be an ogm_ppl.Grid (cells, resolution, origin), got {type(grid).__name__}")
        if not isinstance(sensor, SensorModel):
            raise TypeError(f"sensor must be a SensorModel, got {type(sensor).__name__}")
        if not hasattr(prior, "num_cells"):
            raise TypeError(f"prior must be a MapPrior, got {type(prior).__name__}")
        check_prior_fits(grid, prior)
        compiled = prior.compiled()
        if compiled is None:
            raise ValueError(
                f"OnlineMap needs a prior with a compiled face (prior.compiled()); {type(prior).__name__} has none"
            )
        if compiled.sparse_patches():
            warnings.warn(
                TilePriorWarning(
                    f"OnlineMap updates single cells, and under the tile-table prior {type(prior).__name__} a "
                    "single cell can rarely change without making its tile one the table never counted: the chain "
                    "is exact but barely moves. Map with patch Gibbs over the prior's tiles instead "
                    "(ogm_ppl.exploration.active.RebuildMapper, which explore() uses for such priors)"
                ),
                stacklevel=2,
            )
        for name, v in (("sweeps_per_scan", sweeps_per_scan), ("full_every", full_every), ("margin", margin)):
            if int(v) != v or v < 0:
                raise ValueError(f"{name} must be a non-negative integer, got {v!r}")
        if init_new not in ("keep", "hits", "ogm"):
            raise ValueError(f"init_new must be 'keep', 'hits' or 'ogm', got {init_new!r}")
        self.init_new = init_new
        if initial_rays_per_cell < 1:
            raise ValueError(f"initial_rays_per_cell must be positive, got {initial_rays_per_cell}")
        self.grid, self.sensor, self.prior = grid, sensor, prior
        self.kernel, self.update, self.seed = kernel, update, int(seed)
        self.sweeps_per_scan, self.full_every, self.margin = int(sweeps_per_scan), int(full_every), int(margin)
        self._compiled = compiled
        self._outside = _Outside(prior)
        self._rule = _UPDATES[update]
        K = grid.num_cells
        if isinstance(init, str):
            if init != "free":
                raise ValueError(f"init must be 'free' or a map of {K} cells, got {init!r}")
            m = np.zeros(K, np.uint8)
        else:
            a = np.asarray(torch.as_tensor(init).detach().cpu()).ravel()
            if a.shape != (K,) or not np.isin(a, (0, 1)).all():
                raise ValueError(f"init map must hold {K} values 0/1, got shape {np.shape(init)}")
            m = a.astype(np.uint8)
        # ray side (capacities grow by doubling; rays 0..R-1 live)
        self._R = 0
        self._nnz = 0
        self._scans = 0
        self._readings = 0
        self._beams: int | None = None
        self._max_range: float | None = None
        self._meta: list[dict[str, np.ndarray]] = []  # per add: the Rays fields a model needs
        self._pinned = np.zeros(K, bool)
        self._reached = np.zeros(K, bool)
        # init_new="ogm": traditional OGM log-odds of every scan so far, and the threshold in log-odds
        ogm = init_new == "ogm"
        self._evidence = np.zeros(K if ogm else 0, np.float64)
        self._ogm_touched = np.zeros(K if ogm else 0, bool)
        mean = ogm_start_threshold(prior)
        with np.errstate(divide="ignore"):
            self._ogm_threshold = float(np.log(mean) - np.log1p(-mean))  # -inf / inf at 0 / 1
        self._n_cap = int(initial_rays_per_cell)
        self._b_cap = 0.0
        self._bits = 60
        self.rescales = 0
        self._used = 0
        self._need = np.zeros(grid.num_cells, np.int64)  # scratch of add_cell_entries, kept all zero
        self._st = ok.OnlineState(
            m,
            np.zeros(16, cs.RAY),
            np.zeros(K, np.int64),
            np.zeros(K, cs.INF),
            False,
            np.zeros(17, np.int64),
            np.zeros(16, np.int64),
            np.zeros(K, np.int64),
            np.zeros(K, np.int64),
            np.zeros(K, np.int64),
            np.zeros(1024, np.int32),
            np.zeros(1024, np.int32),
            np.zeros(32, np.float64),
            float(2.0**self._bits),
        )
        self.sweeps_done = 0
        self.full_sweeps = 0
        self._focus = np.zeros(0, np.int64)
        self._latent = np.arange(K, dtype=np.int64)
        self._acc = np.zeros(K, np.float64)
        self._n_acc = 0
        self._model: OccupancyModel | None = None

    # ------------------------------------------------------------------ sizes
    @property
    def num_scans(self) -> int:
        return self._scans

    @property
    def num_rays(self) -> int:
        return self._R

    @property
    def bits(self) -> int:
        """The fixed-point fraction bits ``S`` in use (module docstring)."""
        return self._bits

    @property
    def focus(self) -> np.ndarray:
        """The latent cells of the current focus region (sorted indices)."""
        return self._focus

    @property
    def evidence(self) -> torch.Tensor:
        """Traditional OGM over every scan so far (``K`` log-odds, Haehnel's Delta, from ``l = 0``; Eq. 2.10),
        kept under ``init_new="ogm"``."""
        if self.init_new != "ogm":
            raise AttributeError(f"the evidence grid is kept under init_new='ogm' (this map: {self.init_new!r})")
        return torch.from_numpy(self._evidence.copy())

    @property
    def pinned(self) -> torch.Tensor:
        """``K`` bool: cells holding a pose, pinned free (the offline model's ``known_free``)."""
        return torch.from_numpy(self._pinned.copy())

    @property
    def observed(self) -> np.ndarray:
        """``K`` bool: cells some beam reached (:meth:`~ogm_ppl.raycast.Rays.reached`)."""
        return self._reached.copy()

    def stats(self) -> OnlineStats:
        """Live sizes and allocated capacities."""
        st = self._st
        nbytes = sum(
            getattr(st, f).nbytes
            for f in (
                "m",
                "rays",
                "d",
                "inf",
                "offsets",
                "cells",
                "c_start",
                "c_len",
                "c_cap",
                "c_ray",
                "c_kappa",
                "ll",
            )
        )
        return OnlineStats(
            self._scans,
            self._R,
            self._nnz,
            st.rays.shape[0],
            st.cells.shape[0],
            self._used,
            st.c_ray.shape[0],
            self._bits,
            self.rescales,
            int(nbytes),
        )

    # ------------------------------------------------------------------ adding scans
    def add_scans(
        self,
        scans: Scans,
        sweeps: int | None = None,
        *,
        sensor: SensorModel | None = None,
        grid: Grid | None = None,
    ) -> None:
        """Add ``scans`` to the model and the chain, then run ``sweeps`` sweeps (default
        ``sweeps_per_scan``) by the schedule of the module docstring.

        ``sensor`` / ``grid``: what the scans were taken with / meant for, if the caller knows; they must be
        the map's. Raises ``ValueError`` for scans of another sensor or grid (a different sensor model,
        maximum range or beam count, poses outside the grid) and for scans without a reading."""
        if not isinstance(scans, Scans):
            raise TypeError(f"add_scans takes Scans, got {type(scans).__name__}")
        if sensor is not None and not _same_sensor(sensor, self.sensor):
            raise ValueError(f"scans taken with another sensor model ({sensor!r}) than the map's ({self.sensor!r})")
        if grid is not None and grid != self.grid:
            raise ValueError(f"scans meant for another grid ({grid}) than the map's ({self.grid})")
        if scans.num_scans == 0 or scans.num_valid == 0:
            raise ValueError(
                f"add_scans got {scans.num_scans} scans with no reading (every beam invalid or none): nothing to add"
            )
        if self._max_range is not None and scans.max_range != self._max_range:
            raise ValueError(
                f"scans of maximum range {scans.max_range} m added to a map whose sensor has {self._max_range} m "
                "(another sensor model)"
            )
        if self._beams is not None and scans.beams_per_scan != self._beams:
            raise ValueError(
                f"scans of {scans.beams_per_scan} beams added to a map of {self._beams}-beam scans (another sensor)"
            )
        rays = raycast(self.grid, scans)  # raises on poses outside the grid
        self._add_rays(rays, scans.num_readings)
        self._scans += scans.num_scans
        self._max_range, self._beams = scans.max_range, scans.beams_per_scan
        self.sweep(self.sweeps_per_scan if sweeps is None else int(sweeps), focus=True)

    def _add_rays(self, rays: Rays, num_readings: int) -> None:
        if rays.grid != self.grid:
            raise ValueError("rays were cast on a different grid than the map's")
        n_new = rays.num_rays
        if n_new == 0:
            raise ValueError("add_scans: the scans give no ray")
        # likelihood rows of the new rays only, by the offline model's code (known_free=None: no pinning here);
        # one torch thread: on tables of a scan's size, more threads cost more than they save
        threads = torch.get_num_threads()
        torch.set_num_threads(1)
        try:
            table = OccupancyModel(self.grid, rays, self.sensor, self._outside, known_free=None).loglik_table.numpy()
        finally:
            torch.set_num_threads(threads)
        lengths = rays.lengths
        ragged = table[np.repeat(np.arange(n_new), lengths + 1), _ragged_cols(lengths)]
        bad = np.isnan(ragged) | (ragged == np.inf)
        if bad.any():
            raise ValueError("the sensor model gave NaN / +inf log-likelihoods for the new rays")
        finite = ragged[np.isfinite(ragged)]
        big = float(np.abs(finite).max()) if finite.size else 0.0
        R0, R1 = self._R, self._R + n_new
        if R1 >= 2**31:
            raise ValueError(f"an online map holds fewer than 2^31 rays (the cell index stores int32), got {R1}")
        e0, e1 = self._nnz, self._nnz + rays.nnz
        st = self._st
        # grow the ray side and append
        offsets = _grow(st.offsets, R1 + 1)
        offsets[R0 + 1 : R1 + 1] = e0 + rays.offsets[1:]
        cells = _grow(st.cells, e1)
        cells[e0:e1] = rays.cells
        ll = _grow(st.ll, e1 + R1)
        ll[e0 + R0 : e1 + R1] = ragged
        rec = _grow(st.rays, R1)
        any_inf = bool(st.any_inf or ok.any_impossible(ll, offsets, R0, R1))
        # the fixed-point scale: caps on the rays a cell holds and on |ll| (module docstring), checked
        # before anything is changed so that a refused scan leaves the map as it was
        n_max = int((st.c_len + np.bincount(rays.cells, minlength=self.grid.num_cells)).max())
        n_cap, b_cap = self._n_cap, self._b_cap
        while n_max > n_cap:
            n_cap *= 2
        if big > b_cap:
            b_cap = max(2.0 * big, 2.0 * b_cap, 1.0)
        bits = _bits_for(n_cap, b_cap)
        if bits < cs.MIN_BITS:
            raise ValueError(
                f"likelihood entries up to |{b_cap:.3g}| over up to {n_cap} rays a cell leave "
                f"{bits} fraction bits for the fixed-point sums (need {cs.MIN_BITS})"
            )
        self._n_cap, self._b_cap = n_cap, b_cap
        rescale = False
        c_ray, c_kappa, self._used = ok.add_cell_entries(
            st.c_start, st.c_len, st.c_cap, st.c_ray, st.c_kappa, self._used, offsets, cells, R0, R1, self._need
        )
        if bits != self._bits:
            rescale = R0 > 0
            self._bits = bits
        self._st = st = ok.OnlineState(
            st.m,
            rec,
            st.d,
            st.inf,
            any_inf,
            offsets,
            cells,
            st.c_start,
            st.c_len,
            st.c_cap,
            c_ray,
            c_kappa,
            ll,
            float(2.0**self._bits),
        )
        self._R, self._nnz = R1, e1
        if rescale:  # exact sums of the old rays at the new scale (their terms are finite or counted
            ok.refill_sums(st, R0)  # apart either way: a switch of any_inf needs no refill)
            self.rescales += 1
        ok.add_ray_terms(st, R0, R1)
        # pin the new pose cells free, the state kept in step
        first = np.unique(rays.cells[rays.offsets[:-1]])
        newly = first[~self._pinned[first]]
        self._pinned[first] = True
        ok.set_cells(st, newly, np.zeros(len(newly), np.uint8))
        if len(newly) or R0 == 0:
            self._latent = np.flatnonzero(~self._pinned).astype(np.int64)
        reached = rays.reached()
        if self.init_new == "hits":  # restart the cells these rays are the first to reach (init_new)
            first_seen = reached & ~self._reached & ~self._pinned
            hit = np.zeros(self.grid.num_cells, bool)
            hit[rays.endpoint_cells()] = True
            k = np.flatnonzero(first_seen)
            ok.set_cells(st, k, hit[k].astype(np.uint8))
        elif self.init_new == "ogm":  # restart the latent cells the new rays reach from thresholded OGM
            add_evidence(self._evidence, self._ogm_touched, rays, _HAEHNEL)
            k = np.flatnonzero(reached & ~self._pinned)
            ok.set_cells(st, k, (self._evidence[k] > self._ogm_threshold).astype(np.uint8))
        self._reached |= reached
        # the focus region: where the new rays end, and their first and second hits, dilated
        touched = np.zeros(self.grid.num_cells, bool)
        touched[rays.endpoint_cells()] = True
        ends = st.offsets[R0:R1] + np.minimum(st.rays["f"][R0:R1], lengths - 1)
        touched[st.cells[ends]] = True
        ends = st.offsets[R0:R1] + np.minimum(st.rays["s"][R0:R1], lengths - 1)
        touched[st.cells[ends]] = True
        g = self.grid
        rows, cols = (1, g.num_cells) if g.ndim == 1 else g.shape
        region = ok.dilate(touched, rows, cols, self.margin)
        self._focus = np.ascontiguousarray(region[~self._pinned[region]], dtype=np.int64)
        assert (
            rays.reading is not None and rays.range_len is not None and rays.geometry is not None
        )  # raycast fills them
        self._meta.append(
            {
                "t_enter": rays.t_enter,
                "z": rays.z,
                "is_max": rays.is_max,
                "endpoint_in_grid": rays.endpoint_in_grid,
                "range_cells": rays.range_cells,
                "reading": rays.reading + self._readings,
                "range_len": rays.range_len,
                "geometry": rays.geometry,
            }
        )
        self._readings += num_readings
        self._model = None
        self._acc[:] = 0.0
        self._n_acc = 0

    # ------------------------------------------------------------------ sampling
    def _seed(self, t: int) -> np.uint64:
        x = (self.seed * _MIX + t * 0xBF58476D1CE4E5B9 + 0x94D049BB133111EB) % (1 << 64)
        return np.uint64(x)

    def sweep(self, n: int = 1, focus: bool = True) -> None:
        """Run ``n`` sweeps. ``focus=True``: by the schedule (every ``full_every``-th sweep full, the others
        over the focus region); ``focus=False``: full sweeps. The states are added to :attr:`marginals`."""
        if int(n) != n or n < 0:
            raise ValueError(f"n must be a non-negative integer, got {n!r}")
        for _ in range(int(n)):
            t = self.sweeps_done + 1
            full = (not focus) or (self.full_every > 0 and t % self.full_every == 0) or self._R == 0
            cells = self._latent if full else self._focus
            u = cs.draws(cells, cs.SYSTEMATIC, self._seed(t))[1]
            ok.sweep_accumulate(self._st, cells, self._compiled, u, self._rule, self._acc)
            self._n_acc += 1
            self.sweeps_done = t
            self.full_sweeps += int(full)

    def samples(self, num_samples: int, thin: int = 1, focus: bool = False) -> torch.Tensor:
        """``(num_samples, K)`` uint8 maps: the state after every ``thin`` further sweeps (full sweeps
        unless ``focus``)."""
        if num_samples < 0 or thin < 1:
            raise ValueError(f"num_samples must be >= 0 and thin >= 1, got {num_samples}, {thin}")
        out = torch.empty(int(num_samples), self.grid.num_cells, dtype=torch.uint8)
        for i in range(int(num_samples)):
            self.sweep(thin, focus=focus)
            out[i] = torch.from_numpy(self._st.m.copy())
        return out

    @property
    def marginals(self) -> torch.Tensor:
        """``(K,)`` float64: the mean of the states after each sweep since the last :meth:`add_scans`
        (the current state if none ran)."""
        if self._n_acc == 0:
            return torch.from_numpy(self._st.m.astype(np.float64))
        return torch.from_numpy(self._acc / self._n_acc)

    def reset_marginals(self) -> None:
        """Start the running mean of :attr:`marginals` afresh (e.g. after a burn-in)."""
        self._acc[:] = 0.0
        self._n_acc = 0

    @property
    def state(self) -> torch.Tensor:
        """``(K,)`` uint8: the current map (a copy)."""
        return torch.from_numpy(self._st.m.copy())

    def set_state(self, m) -> None:
        """Make map ``m`` (``K`` values 0/1; pinned cells must be 0) the state, flipping the cells that
        differ with the kept state in step."""
        a = np.asarray(torch.as_tensor(m).detach().cpu()).ravel()
        K = self.grid.num_cells
        if a.shape != (K,) or not np.isin(a, (0, 1)).all():
            raise ValueError(f"a state is {K} values 0/1, got shape {a.shape}")
        if (a[self._pinned] != 0).any():
            raise ValueError("the state occupies a pinned (pose) cell")
        st = self._st
        for k in np.flatnonzero(a.astype(np.uint8) != st.m).tolist():
            ok.set_cell(st, int(k), int(a[k]))

    def cell_log_odds(self, k: int) -> float:
        """``l(m_k | z, m_{-k})`` at the current state (Eq. 4.2): prior plus the kept likelihood ratio."""
        return float(cs.prior_log_odds(self._compiled, int(k), self._st.m) + ok.log_lik_ratio(self._st, int(k)))

    # ------------------------------------------------------------------ the offline view
    @property
    def rays(self) -> Rays:
        """Every ray added so far as one :class:`~ogm_ppl.raycast.Rays` (the ray order of
        :func:`~ogm_ppl.raycast.raycast` on all scans concatenated)."""
        if self._R == 0:
            raise ValueError("the online map holds no scans yet")
        st = self._st
        cat = {k: np.concatenate([m[k] for m in self._meta]) for k in self._meta[0]}
        return Rays(
            grid=self.grid,
            offsets=st.offsets[: self._R + 1].copy(),
            cells=st.cells[: self._nnz].copy(),
            **cat,
        )

    @property
    def model(self) -> OccupancyModel:
        """The :class:`~ogm_ppl.models.occupancy.OccupancyModel` given every scan so far (built on first
        use after each :meth:`add_scans`, from the kept rays: no ray casting)."""
        if self._model is None:
            self._model = OccupancyModel(self.grid, self.rays, self.sensor, self.prior)
        return self._model

    def kept_state(self) -> dict[str, np.ndarray]:
        """Copies of the chain's kept state: ``m`` (``K``), ``f``, ``s`` (``R``), ``d`` (``K`` int64, units
        of ``2^-bits``), ``inf_pos``, ``inf_neg`` (``K``) and the ragged table ``ll`` (``nnz + R``)."""
        st = self._st
        return {
            "m": st.m.copy(),
            "f": st.rays["f"][: self._R].copy(),
            "s": st.rays["s"][: self._R].copy(),
            "d": st.d.copy(),
            "inf_pos": st.inf["pos"].copy(),
            "inf_neg": st.inf["neg"].copy(),
            "ll": st.ll[: self._nnz + self._R].copy(),
        }


class _Outside:
    """What the likelihood rows read of the prior: its size and ``lambda_out`` (computed once)."""

    def __init__(self, prior) -> None:
        self.num_cells = prior.num_cells
        self._lam = float(prior.outside_occupancy())

    def outside_occupancy(self) -> float:
        return self._lam


def _ragged_cols(lengths: np.ndarray) -> np.ndarray:
    """``0..len_r`` for every ray, concatenated."""
    n = lengths + 1
    return np.arange(int(n.sum())) - np.repeat(np.cumsum(n) - n, n)


@dataclass
class Replay:
    """What :func:`replay` returns: the final marginals (``K``), the observed cells (``K`` bool), the
    snapshots ``(scans so far, K marginals)``, the seconds each scan took (add + sweeps) and the chain."""

    probabilities: np.ndarray
    observed: np.ndarray
    snapshots: list[tuple[int, np.ndarray]]
    seconds_per_scan: np.ndarray
    online: OnlineMap


def replay(
    grid: Grid,
    scans: Scans,
    sensor: SensorModel,
    prior,
    *,
    burn_in: int = 0,
    sweeps: int = 100,
    snapshot_every: int | None = None,
    progress: bool = False,
    **online_kw,
) -> Replay:
    """Replay ``scans`` one scan at a time into an :class:`OnlineMap` (``online_kw``: its options), then
    run ``burn_in`` full sweeps and ``sweeps`` full sweeps whose mean is the map. ``snapshot_every = k``
    keeps the marginals (of the sweeps since the latest scan) after every ``k``-th scan."""
    import time

    if snapshot_every is not None and snapshot_every < 1:
        raise ValueError(f"snapshot_every must be a positive number of scans, got {snapshot_every}")
    om = OnlineMap(grid, sensor, prior, **online_kw)
    S = scans.num_scans
    times = np.zeros(S)
    snaps: list[tuple[int, np.ndarray]] = []
    from ogm_ppl.progress import Progress

    assert scans.valid is not None  # Scans.__post_init__ always sets the S x B mask
    # a bar on a terminal; elsewhere a plain line every 10 s once the replay has taken 10 s
    with Progress(S, "online scans", unit="scan", enabled=progress, after=10.0) as bar:
        for i in range(S):
            bar.update()
            if not scans.valid[i].any():
                continue  # a scan without a reading adds nothing
            t0 = time.perf_counter()
            om.add_scans(_one(scans, i))
            times[i] = time.perf_counter() - t0
            if snapshot_every is not None and (i + 1) % snapshot_every == 0:
                snaps.append((i + 1, om.marginals.numpy().copy()))
    om.sweep(burn_in, focus=False)
    om.reset_marginals()
    om.sweep(sweeps, focus=False)
    return Replay(om.marginals.numpy().copy(), om.observed, snaps, times, om)


def _one(scans: Scans, i: int) -> Scans:
    assert scans.valid is not None
    return Scans(
        scans.poses[i : i + 1],
        scans.angles[i : i + 1],
        scans.ranges[i : i + 1],
        scans.max_range,
        valid=scans.valid[i : i + 1],
        min_range=scans.min_range,
    )
