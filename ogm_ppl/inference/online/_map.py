"""The online map: an :class:`OnlineMap` holds the scans added so far (in the growing ray store of
``_store``), the single-cell Gibbs chain over them, and the schedule of its focused and full sweeps
(:mod:`ogm_ppl.inference.online`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from ogm_ppl.grid import Grid
from ogm_ppl.inference._kernels import cell_sweep as cs
from ogm_ppl.inference._kernels import online as ok
from ogm_ppl.inference.log_odds.maps import add_evidence
from ogm_ppl.inference.mcmc.kernel import ogm_start_threshold
from ogm_ppl.inference.online._checks import _UPDATES, check_options, check_scans, start_map
from ogm_ppl.inference.online._store import (
    _Outside,
    append_rays,
    empty_state,
    focus_region,
    likelihood_rows,
    ray_fields,
    scale_caps,
)
from ogm_ppl.models.delta import Moravec
from ogm_ppl.models.occupancy import OccupancyModel
from ogm_ppl.raycast import Rays, raycast
from ogm_ppl.scans import Scans
from ogm_ppl.sensors import SensorModel

_MIX = 0x9E3779B97F4A7C15
_HAEHNEL = Moravec.haehnel()  # the update term of the thresholded-OGM start (initial_map's default)


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


class OnlineMap:
    """An online single-cell Gibbs chain over the map given every scan added so far (the growth, the fixed-point
    scale and the schedule: :mod:`ogm_ppl.inference.online`).

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
        initial_rays_per_cell: the first cap ``n_cap`` of the fixed-point scale.

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
        compiled = check_options(
            grid, sensor, prior, kernel, update, sweeps_per_scan, full_every, margin, init_new, initial_rays_per_cell
        )
        self.init_new = init_new
        self.grid, self.sensor, self.prior = grid, sensor, prior
        self.kernel, self.update, self.seed = kernel, update, int(seed)
        self.sweeps_per_scan, self.full_every, self.margin = int(sweeps_per_scan), int(full_every), int(margin)
        self._compiled = compiled
        self._outside = _Outside(prior)
        self._rule = _UPDATES[update]
        K = grid.num_cells
        m = start_map(init, K)
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
        self._st = empty_state(m, self._bits)
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
        """The fixed-point fraction bits ``S`` in use."""
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
        ``sweeps_per_scan``) by the schedule of :mod:`ogm_ppl.inference.online`.

        ``sensor`` / ``grid``: what the scans were taken with / meant for, if the caller knows; they must be
        the map's. Raises ``ValueError`` for scans of another sensor or grid (a different sensor model,
        maximum range or beam count, poses outside the grid) and for scans without a reading."""
        check_scans(scans, sensor, grid, self.sensor, self.grid, self._max_range, self._beams)
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
        ragged, big = likelihood_rows(self.grid, rays, self.sensor, self._outside)
        R0, R1 = self._R, self._R + n_new
        if R1 >= 2**31:
            raise ValueError(f"an online map holds fewer than 2^31 rays (the cell index stores int32), got {R1}")
        e0, e1 = self._nnz, self._nnz + rays.nnz
        st = self._st
        offsets, cells, ll, rec = append_rays(st, rays, ragged, R0, e0)
        any_inf = bool(st.any_inf or ok.any_impossible(ll, offsets, R0, R1))
        # the fixed-point scale: caps on the rays a cell holds and on |ll| (_store.scale_caps), checked
        # before anything is changed so that a refused scan leaves the map as it was
        n_max = int((st.c_len + np.bincount(rays.cells, minlength=self.grid.num_cells)).max())
        n_cap, b_cap, bits = scale_caps(n_max, big, self._n_cap, self._b_cap)
        self._n_cap, self._b_cap = n_cap, b_cap
        rescale = False
        c_ray, c_kappa, self._used = ok.add_cell_entries(st, self._used, offsets, cells, R0, R1, self._need)
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
        self._focus = focus_region(st, rays, R0, R1, self.margin, self._pinned)
        self._meta.append(ray_fields(rays, self._readings))
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
