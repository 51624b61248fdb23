r"""The occupancy map as a Pyro model (Section 2.1, 2.6): ``m ~ prior``, ``z_n ~ p(z_n | f_n(m))``.

.. math::
    p(m, z) = p(m) \prod_{n=1}^N p(z_n \mid f_n(m))

where ``f_n(m)`` is the first occupied cell along ray ``n`` (static world, Section 2.6). Readings are in
kappa units along their ray (:mod:`ogm_ppl.raycast`), so every ray's likelihood is a lookup table over its
``F_n + 2`` first-hit values (``f = 0..F_n`` and "none"), computed once from the sensor model.

**Rays cut by the grid edge.** The sensor's ray has ``F_n + 1`` cells up to its maximum range
(``rays.range_len``); the grid holds the first ``len_n`` of them. The cells beyond the edge are cells the
map does not hold: they are marginalised under the prior's occupancy of a cell outside the map,
``lambda_out`` (:meth:`~ogm_ppl.priors.MapPrior.outside_occupancy`, independent cells), so the "no
occupied cell in the grid" column is

.. math::
    p(z \mid f > len_n - 1) = \sum_{j = len_n}^{F_n} \lambda_{out} (1 - \lambda_{out})^{j - len_n}
        p(z \mid f = j; F_n) + (1 - \lambda_{out})^{F_n + 1 - len_n} p(z \mid \text{none}; F_n)

and every column censors max range at the sensor's ``F_n``, not at the grid edge. Each ray's likelihood
is thereby a normalised distribution over readings for every map (tested by summing it). Cells holding a
sensor are known to be free (the robot is not inside a wall); they are pinned to 0 and are not latent.

**The Pyro model** (:meth:`OccupancyModel.model`) has two sample sites:

* ``"m"`` — the *latent* cells only (event shape ``L = len(model.latent)``, in the order of
  ``model.latent``), drawn from the prior given that the pinned cells are free; :meth:`OccupancyModel.full_map`
  turns values of ``"m"`` into ``K`` maps (the deterministic site ``"map"`` records the full map). For
  compatibility a full ``K`` map is also accepted as the value of ``"m"`` (conditioning, MCMC kernels that
  return ``K`` maps); its pinned cells must then be 0 (``-inf`` otherwise).
* ``"z"`` — the readings, an observed :class:`ReadingsDistribution` site (event shape ``R``). A value is
  each ray's measured range in cells; a max-range reading is encoded as the ray's maximum range
  (``rays.max_range_cells()``), as in :class:`~ogm_ppl.scans.Scans`. ``model.model(readings=None)`` (or
  ``poutine.uncondition``) simulates readings; ``pyro.condition(model.model, data={"z": new})`` scores new
  readings of the same rays.

>>> import pyro, torch
>>> from pyro.infer import Predictive
>>> from ogm_ppl import GaussianRange, OccupancyModel, raycast
>>> from ogm_ppl.datasets import toy_1d
>>> from ogm_ppl.priors import IndependentPrior
>>> toy = toy_1d(num_cells=10, wall=5, readings=[5.0, 6.0])
>>> model = OccupancyModel(toy.grid, raycast(toy.grid, toy.scans), GaussianRange(1.0, 1e-3), IndependentPrior(0.3, 10))
>>> sim = Predictive(model.model, num_samples=4)(readings=None)
>>> tuple(sim["m"].shape), tuple(sim["map"].shape), tuple(sim["z"].shape)
((4, 9), (4, 10), (4, 2))
"""

from __future__ import annotations

import math

import numpy as np
import pyro
import pyro.distributions as dist
import torch
from pyro.distributions.torch_distribution import TorchDistribution
from torch.distributions import constraints

from ogm_ppl._memory import available_memory, check_fits
from ogm_ppl._validate import as_binary_maps, check_binary
from ogm_ppl.priors.base import MapPrior
from ogm_ppl.raycast import CAST_BYTES_PER_CELL, CAST_BYTES_PER_RAY, Rays, ray_cast_size
from ogm_ppl.sensors import SensorModel

_TABLE_BLOCK = 1 << 22  # table entries per block of rays in OccupancyModel._loglik_table (32 MB of float64)

__all__ = ["OccupancyModel", "MapDistribution", "ReadingsDistribution", "OBSERVED"]

#: default of ``OccupancyModel.model(readings=...)``: the model's own readings.
OBSERVED = "observed"


class MapDistribution(TorchDistribution):
    """A Pyro distribution over binary maps defined by a :class:`MapPrior`, given that the ``known_free``
    cells are free.

    The event is the latent cells (event shape ``L``, those not in ``known_free``, in index order);
    without ``known_free`` it is the whole map (``K``). ``sample`` draws from the prior conditioned on the
    pinned cells being free (:meth:`~ogm_ppl.priors.MapPrior.sample_given_free`); ``log_prob`` is
    ``log p(m_latent, m_pinned = 0)`` (the joint with the known-free observation, i.e. the conditional up
    to the constant ``log P(m_pinned = 0)``), so a trace's ``log_prob_sum`` is the model's log joint.
    ``log_prob`` also accepts full ``K`` maps (``-inf`` where a pinned cell is occupied) and raises on
    values other than 0/1 or on NaN from the prior.
    """

    arg_constraints: dict = {}
    support = constraints.independent(constraints.boolean, 1)
    has_enumerate_support = False

    def __init__(self, prior, known_free: torch.Tensor | None = None, batch_shape=torch.Size(), validate_args=None):
        self.prior = prior
        K = prior.num_cells
        self.known_free = (
            torch.zeros(K, dtype=torch.bool) if known_free is None else torch.as_tensor(known_free, dtype=torch.bool)
        )
        if self.known_free.shape != (K,):
            raise ValueError(
                f"known_free must be a boolean mask of {K} cells, got shape {tuple(self.known_free.shape)}"
            )
        self.latent = torch.nonzero(~self.known_free).flatten()
        super().__init__(torch.Size(batch_shape), torch.Size([len(self.latent)]), validate_args=validate_args)

    def expand(self, batch_shape, _instance=None):
        return MapDistribution(self.prior, self.known_free, batch_shape)

    def full_map(self, value: torch.Tensor) -> torch.Tensor:
        """``... x L`` (or ``... x K``) values -> ``... x K`` maps (pinned cells 0)."""
        value = torch.as_tensor(value)
        K, L = self.prior.num_cells, len(self.latent)
        if value.shape[-1:] == (K,):
            return value
        if value.shape[-1:] != (L,):
            raise ValueError(
                f"site 'm' takes the {L} latent cells (or a full map of {K}), got shape {tuple(value.shape)}"
            )
        out = value.new_zeros(value.shape[:-1] + (K,))
        out[..., self.latent] = value
        return out

    def sample(self, sample_shape=torch.Size()):
        shape = torch.Size(sample_shape) + self.batch_shape
        if type(self.prior).sample is MapPrior.sample:
            raise TypeError(
                f"{type(self.prior).__name__} has no sample(): the model cannot draw maps from it (prior "
                "predictive, Predictive, init_to_sample). Implement MapPrior.sample, or give MCMC/SVI an "
                "initial map / a guide for site 'm'"
            )
        maps = self.prior.sample_given_free(self.known_free, shape)
        maps = torch.as_tensor(maps, dtype=torch.float64)
        if maps.shape != shape + (self.prior.num_cells,) or not ((maps == 0) | (maps == 1)).all():
            raise ValueError(
                f"{type(self.prior).__name__}.sample returned values other than 0/1 maps of shape "
                f"{tuple(shape + (self.prior.num_cells,))} (NaN parameters?)"
            )
        return maps[..., self.latent]

    def log_prob(self, value):
        value = torch.as_tensor(value)
        full = self.full_map(value).to(torch.float64)
        _check_binary(full, "value of site 'm'")
        lp = self.prior.log_prob(full)
        if torch.isnan(lp).any():
            raise ValueError(f"{type(self.prior).__name__}.log_prob returned NaN")
        if value.shape[-1] != len(self.latent):
            lp = torch.where((full[..., self.known_free] == 0).all(-1), lp, -math.inf)
        return lp


_check_binary = check_binary


class ReadingsDistribution(TorchDistribution):
    r"""The readings given maps: ``prod_n p(z_n | f_n(m))`` (event shape ``R``, batch shape the maps').

    A value is every ray's measured range in cells, max-range readings at the ray's maximum range
    (``rays.max_range_cells()``). ``log_prob`` of the model's own readings reads the cached likelihood
    table; for other readings of the same rays it builds their table (continuous kappa ``r + 1/2`` or the
    kappa of the range, :mod:`ogm_ppl.raycast`). ``sample`` draws readings: the first hit of each ray
    (past the grid edge: under ``lambda_out``), then the sensor's reading, converted back to a range.
    """

    arg_constraints: dict = {}
    support = constraints.independent(constraints.real, 1)

    def __init__(self, model: OccupancyModel, maps: torch.Tensor, validate_args=None):
        self.model = model
        self.maps = maps
        super().__init__(maps.shape[:-1], torch.Size([model.rays.num_rays]), validate_args=validate_args)

    def expand(self, batch_shape, _instance=None):
        K = self.maps.shape[-1]
        return ReadingsDistribution(self.model, self.maps.expand(torch.Size(batch_shape) + (K,)))

    def log_prob(self, value):
        m = self.model
        value = torch.as_tensor(value, dtype=torch.float64)
        R = m.rays.num_rays
        if value.shape[-1:] != (R,):
            raise ValueError(f"site 'z' takes one reading per ray ({R}), got shape {tuple(value.shape)}")
        f = m.first_hits(self.maps)  # B x R
        flat = value.reshape(-1, R)
        tables = torch.stack([m.loglik_table if torch.equal(v, m.readings) else m.loglik_table_for(v) for v in flat])
        tables = tables.reshape(value.shape[:-1] + tables.shape[-2:])
        batch = torch.broadcast_shapes(value.shape[:-1], f.shape[:-1])
        tables = tables.expand(batch + tables.shape[-2:])
        f = f.expand(batch + f.shape[-1:])
        return torch.gather(tables, -1, f[..., None])[..., 0].sum(-1)

    def sample(self, sample_shape=torch.Size()):
        shape = torch.Size(sample_shape) + self.batch_shape
        maps = self.maps.expand(shape + self.maps.shape[-1:])
        return self.model.simulate_readings(maps)


#: bytes per ray-cell crossing allowed for a model and one Gibbs kernel over it (likelihood table, ray index in
#: ray and cell order, first hits), beside the table's block temporaries below; with them an upper bound of the
#: peak: ``benchmarks/bench_memory.py`` measures the peak of model, kernel and one sweep at 0.5-0.85 of
#: :func:`memory_needed` on real logs of 3 M to 66 M crossings
BYTES_PER_CROSSING = 64
#: float64 temporaries of one block of the likelihood table (the sensor's ``log_prob`` and the masks; up to
#: ``_TABLE_BLOCK`` entries each): about 0.6 GB once a table has that many entries, whatever the crossings
TABLE_TEMPORARIES = 18


def memory_needed(rays: Rays) -> int:
    """Bytes a model over ``rays`` and a Gibbs kernel may need at their peak (an upper bound, measured by
    ``benchmarks/bench_memory.py``): :data:`BYTES_PER_CROSSING` per
    ray-cell crossing and :data:`TABLE_TEMPORARIES` float64 blocks of the likelihood table (``R x W`` entries,
    ``W`` the longest ray plus one, at most ``_TABLE_BLOCK`` a block)."""
    entries = int(rays.num_rays) * (int(rays.lengths.max(initial=0)) + 1)
    return int(rays.cells.size) * BYTES_PER_CROSSING + TABLE_TEMPORARIES * 8 * min(entries, _TABLE_BLOCK)


def check_ray_cast_memory(grid, scans, model: bool = False) -> None:
    """Refuse (``MemoryError``, with the numbers) a ray cast of ``scans`` on ``grid`` that would not fit in this
    machine's free memory, before it runs (:func:`~ogm_ppl.raycast.ray_cast_size`): the cast's buffers alone, or
    (``model``) with a model and a sampler over its rays (:func:`memory_needed` of the crossings it will find,
    less the 12 bytes a crossing the buffers already hold)."""
    size = ray_cast_size(grid, scans)
    need = size.cast_bytes
    basis = (
        f"{CAST_BYTES_PER_CELL} bytes for each of the {size.capacity:,} cells it makes room for, all "
        f"{size.rays:,} rays up to the sensor's maximum range, and {CAST_BYTES_PER_RAY} a ray"
    )
    what = f"the ray cast on a {' x '.join(map(str, grid.shape))} grid"
    if model:
        entries = size.rays * (size.longest + 1)
        need += size.crossings * (BYTES_PER_CROSSING - CAST_BYTES_PER_CELL)
        need += TABLE_TEMPORARIES * 8 * min(entries, _TABLE_BLOCK)
        what = f"{what} and a model and sampler over its rays"
        basis += (
            f", then {BYTES_PER_CROSSING - CAST_BYTES_PER_CELL} more bytes for each of the up to "
            f"{size.crossings:,} cells the rays cross inside the grid and the likelihood table's working blocks"
        )
    check_fits(
        need,
        f"{what} ({basis})",
        "use a coarser resolution, fewer scans or beams, or a shorter usable range",
    )


def check_memory(rays: Rays) -> None:
    """Refuse (``MemoryError``, with the numbers) a model whose rays need more than this machine's free memory
    (:func:`memory_needed`), before the likelihood table is built: a map too fine or a log too long for the
    machine fails at once instead of swapping."""
    crossings = int(rays.cells.size)
    need = memory_needed(rays)
    have = available_memory()
    if have is not None and need > have:
        raise MemoryError(
            f"the model's {rays.num_rays:,} rays cross {crossings:,} cells on a {rays.grid.shape} grid: about "
            f"{need / 2**30:.1f} GiB for the model and a sampler ({BYTES_PER_CROSSING} bytes a crossing and the "
            "likelihood table's working blocks), more than "
            f"the {have / 2**30:.1f} GiB this machine has free; use a coarser resolution, fewer scans or beams, or "
            "a shorter usable range"
        )


def check_prior_fits(grid, prior) -> None:
    """Refuse (``ValueError``) a prior of another number of cells than ``grid``, or one laid out on another
    shape (a prior with ``rows`` and ``cols``, e.g. built for ``(80, 60)`` on a ``60 x 80`` grid: same cell
    count, transposed neighbourhoods)."""
    if prior.num_cells != grid.num_cells:
        raise ValueError(f"prior has {prior.num_cells} cells, the grid {grid.num_cells}")
    rows, cols = getattr(prior, "rows", None), getattr(prior, "cols", None)
    layout = (1, grid.num_cells) if grid.ndim == 1 else tuple(grid.shape)
    if rows is not None and cols is not None and (int(rows), int(cols)) != layout:
        raise ValueError(
            f"{type(prior).__name__} is laid out on {int(rows)} x {int(cols)} cells, the grid on "
            f"{layout[0]} x {layout[1]}: build the prior for the grid's shape ({tuple(grid.shape)})"
        )


class OccupancyModel:
    """The map model: grid, rays, forward sensor model and a pluggable prior.

    Args:
        grid: the grid (``K`` cells).
        rays: from :func:`~ogm_ppl.raycast.raycast` on that grid (at least one ray).
        sensor: a :class:`~ogm_ppl.sensors.SensorModel`.
        prior: a :class:`~ogm_ppl.priors.MapPrior` over ``K`` cells.
        known_free: cells pinned free: ``"sensor"`` (default, the cells holding a pose), ``None``, or an
            index array.

    Attributes:
        loglik_table: ``R x W`` float64, ``log p(z_r | f)`` for ``f = 0..len_r - 1`` and, at column
            ``len_r``, for no occupied cell on the ray; ``-inf`` padding beyond.
        latent: indices of the cells that are not pinned.
    """

    def __init__(self, grid, rays: Rays, sensor: SensorModel, prior, known_free="sensor") -> None:
        if not isinstance(sensor, SensorModel):
            raise TypeError(f"sensor must be a SensorModel (e.g. GaussianRange(sigma_cells)), got {sensor!r}")
        if not hasattr(prior, "num_cells"):
            raise TypeError(f"prior must be a MapPrior (e.g. IndependentPrior(0.5, grid.num_cells)), got {prior!r}")
        if rays.grid != grid:
            raise ValueError("rays were cast on a different grid")
        if rays.num_rays == 0:
            raise ValueError("OccupancyModel needs at least one ray (the ray set is empty)")
        check_prior_fits(grid, prior)
        check_memory(rays)
        self.grid, self.rays, self.sensor, self.prior = grid, rays, sensor, prior
        K = grid.num_cells
        if isinstance(known_free, str):
            if known_free != "sensor":
                raise ValueError(f"known_free must be 'sensor', None or indices, got {known_free!r}")
            known_free = np.unique(rays.cells[rays.offsets[:-1]])
        free = np.zeros(K, dtype=bool)
        if known_free is not None:
            idx = np.asarray(known_free, dtype=np.int64)
            if idx.size and (idx.min() < 0 or idx.max() >= K):
                raise ValueError(f"known_free holds a cell outside 0..{K - 1}")
            free[idx] = True
        self.known_free = torch.from_numpy(free)
        self.latent = torch.from_numpy(np.flatnonzero(~free))
        self.lengths = torch.from_numpy(rays.lengths)
        self.loglik_table = self._loglik_table()
        self._dense = None
        self._readings = None
        self._entries = None

    @property
    def num_cells(self) -> int:
        return self.grid.num_cells

    def ray_index(self):
        """The rays, their transposed index and :attr:`loglik_table` as one
        :class:`~ogm_ppl.raycast.RayIndex` (built once per table) for the compiled kernels."""
        cached = getattr(self, "_ray_index", None)
        if cached is None or cached[0] is not self.loglik_table:
            cached = (self.loglik_table, self.rays.index(self.loglik_table.numpy()))
            self._ray_index = cached
        return cached[1]

    def _loglik_table(self, range_cells=None, z_kappa=None, is_max=None) -> torch.Tensor:
        """``R x W`` table for the model's readings, or for other readings of the same rays (``R`` each:
        range in cells, kappa of the reading, max-range flags).

        Built in blocks of rays (about ``_TABLE_BLOCK`` table entries each), so the peak memory is the table
        plus a few blocks, not a dozen ``R x W`` temporaries (Intel at 2 cm: 80,000 rays x 1,000 cells);
        a tqdm bar shows progress when there are many blocks.
        """
        r = self.rays
        assert r.range_len is not None  # Rays.__post_init__ always fills it
        lengths_np = r.lengths
        lengths = torch.from_numpy(lengths_np)
        range_len = torch.from_numpy(np.maximum(r.range_len, lengths_np))
        R, W = r.num_rays, int(lengths_np.max()) + 1
        if range_cells is None:
            range_cells, z_kappa, is_max = r.range_cells, r.z, r.is_max.copy()
        is_max = torch.as_tensor(is_max, dtype=torch.bool)
        bad = (torch.as_tensor(z_kappa) < 0) & ~is_max
        if bad.any():
            raise ValueError(f"reading of ray {int(bad.nonzero()[0, 0])} lies before its ray")
        continuous = self.sensor.continuous_range
        if continuous:  # continuous kappa t + 1/2 (ogm_ppl.sensors)
            z = torch.as_tensor(range_cells).to(torch.float64) + 0.5
            F = torch.from_numpy(r.max_range_cells()).to(torch.float64)
        else:
            z = torch.as_tensor(z_kappa).to(torch.float64)
            F = (range_len - 1).to(torch.float64)  # the sensor's last kappa, beyond the grid edge if cut
        table = torch.empty(R, W, dtype=torch.float64)
        rows = max(1, _TABLE_BLOCK // W)
        blocks = range(0, R, rows)
        if len(blocks) > 8:
            from tqdm import tqdm  # (not tqdm.auto: a notebook without ipywidgets warns)

            blocks = tqdm(blocks, desc="likelihood table", unit="block", leave=False, disable=None)
        offsets = r.offsets
        for a in blocks:
            b = min(R, a + rows)
            n, Wb = lengths_np[a:b], int(lengths_np[a:b].max()) + 1
            col = torch.arange(Wb, dtype=torch.float64)[None, :]
            none_col = col == lengths[a:b, None]
            if continuous:
                e0, e1 = int(offsets[a]), int(offsets[b])
                t = torch.zeros(b - a, Wb, dtype=torch.float64)
                row = np.repeat(np.arange(b - a), n)
                kappa = np.arange(e1 - e0) - np.repeat(offsets[a:b] - e0, n)
                t[torch.from_numpy(row), torch.from_numpy(kappa)] = torch.from_numpy(r.t_enter[e0:e1]).double()
                t[:, 0] = -0.5  # the sensor's own cell sits at kappa_c = 0 (ogm_ppl.sensors)
                f = torch.where(none_col, F[a:b, None] + 1, t + 0.5)
                del t
            else:
                f = torch.where(none_col, F[a:b, None] + 1, col)
            block = self.sensor.log_prob(
                z[a:b, None].expand(-1, Wb), f, F[a:b, None], is_max[a:b, None].expand(-1, Wb)
            ).to(torch.float64)
            block = torch.where(col <= lengths[a:b, None], block, -math.inf)
            if torch.isnan(block).any():
                raise ValueError("the sensor model returned NaN log-likelihoods")
            table[a:b, :Wb] = block
            table[a:b, Wb:] = -math.inf
        cut = torch.nonzero(range_len > lengths).flatten()
        if len(cut):
            none = self._beyond_edge(cut, z[cut], F[cut], is_max[cut], lengths[cut], range_len[cut])
            if torch.isnan(none).any():
                raise ValueError("the sensor model returned NaN log-likelihoods")
            table[cut, lengths[cut]] = none
        return table

    def _beyond_edge(self, rays, z, F, is_max, lengths, range_len, chunk: int = 4096) -> torch.Tensor:
        """``log p(z | no occupied cell in the grid)`` for rays cut by the grid edge: the cells beyond it
        marginalised under independent occupancy ``lambda_out`` (module docstring)."""
        lam = float(self.prior.outside_occupancy())
        if not 0.0 <= lam <= 1.0:
            raise ValueError(f"prior.outside_occupancy() must lie in [0, 1], got {lam}")
        log_on = math.log(lam) if lam > 0 else -math.inf
        log_off = math.log1p(-lam) if lam < 1 else -math.inf
        out = torch.empty(len(z), dtype=torch.float64)
        for a in range(0, len(z), chunk):
            sl = slice(a, a + chunk)
            n_out = range_len[sl] - lengths[sl]
            J = int(n_out.max()) + 1  # i = 0..n_out - 1: first hit at lengths + i; i = n_out: none
            i = torch.arange(J, dtype=torch.float64)[None, :]
            none = i == n_out[:, None]
            if self.sensor.continuous_range:
                off, t = self.rays.entries_beyond_edge(rays[sl].numpy())
                if not np.array_equal(np.diff(off), n_out.numpy()):
                    raise RuntimeError("entry distances past the grid edge disagree with Rays.range_len")
                te = torch.zeros(len(n_out), J, dtype=torch.float64)
                idx = torch.from_numpy(np.repeat(np.arange(len(n_out)), np.diff(off)))
                pos = torch.from_numpy(np.arange(len(t)) - np.repeat(off[:-1], np.diff(off)))
                te[idx, pos] = torch.from_numpy(t)
                f = torch.where(none, F[sl, None] + 1, te + 0.5)
            else:
                f = torch.where(none, F[sl, None] + 1, lengths[sl, None] + i)
            lz = self.sensor.log_prob(z[sl, None].expand(-1, J), f, F[sl, None], is_max[sl, None].expand(-1, J))
            # log weight: lambda (1 - lambda)^i for a first hit at lengths + i, (1 - lambda)^n_out for none
            pow_off = torch.where(i == 0, 0.0, i * log_off) if lam == 1 else i * log_off
            lw = torch.where(none, pow_off, log_on + pow_off)
            lw = torch.where(i > n_out[:, None], -math.inf, lw)
            out[sl] = torch.logsumexp(lz.to(torch.float64) + lw, dim=-1)
        return out

    # ------------------------------------------------------------ readings
    @property
    def readings(self) -> torch.Tensor:
        """``R`` float64: the value of site ``"z"`` for the model's readings (range in cells; max-range
        readings at the ray's maximum range)."""
        if self._readings is None:
            r = self.rays
            F = torch.from_numpy(r.max_range_cells()).to(torch.float64)
            self._readings = torch.where(
                torch.from_numpy(r.is_max.copy()), F, torch.from_numpy(r.range_cells).to(torch.float64)
            )
        return self._readings

    def _entry_table(self) -> torch.Tensor:
        """``R x W`` entry distances of the model's rays (:func:`entry_table`), built once."""
        if self._entries is None:
            self._entries = entry_table(self.rays)
        return self._entries

    def range_to_kappa(self, ranges: torch.Tensor) -> torch.Tensor:
        """The kappa of readings (``... x R`` ranges in cells) on the model's rays (:func:`range_to_kappa`)."""
        return range_to_kappa(self._entry_table(), ranges)

    def loglik_table_for(self, readings: torch.Tensor) -> torch.Tensor:
        """The ``R x W`` likelihood table (as :attr:`loglik_table`) of other readings of the same rays
        (``R``: values of site ``"z"``)."""
        readings = torch.as_tensor(readings, dtype=torch.float64)
        if readings.shape != (self.rays.num_rays,):
            raise ValueError(
                f"readings must be {self.rays.num_rays} numbers, one per ray, got shape {tuple(readings.shape)}"
            )
        F = torch.from_numpy(self.rays.max_range_cells()).to(torch.float64)
        # a continuous sensor's noise reaches below zero (GaussianRange: a first hit near the sensor reads
        # negative ranges, as simulate_readings draws them); a discrete sensor reads cells, from zero
        continuous = self.sensor.continuous_range
        bad = ~torch.isfinite(readings) | (readings > F) | (False if continuous else readings < 0)
        if bad.any():
            i = int(torch.nonzero(bad)[0])
            lo = "up to" if continuous else "in [0,"
            raise ValueError(
                f"readings must be ranges in cells {lo} the ray's max range{'' if continuous else ']'} (a max-range "
                f"reading is the max range itself); {int(bad.sum())} are not, the first on ray {i}: "
                f"{float(readings[i])!r} (max range {float(F[i]):g})"
            )
        is_max = readings >= F
        return self._loglik_table(readings, self.range_to_kappa(readings), is_max)

    def simulate_readings(self, maps: torch.Tensor, generator: torch.Generator | None = None) -> torch.Tensor:
        """Readings (``... x R``, values of site ``"z"``) drawn from the sensor given maps ``... x K``: every
        ray's first hit (a ray cut by the grid edge with no hit in the grid draws the cells beyond under
        ``lambda_out``), the sensor's reading, converted back to a range in cells.

        Maps with an occupied pinned cell (a sensor inside a wall: zero mass under the model) are refused
        (``ValueError``). With ``known_free=None`` the sensor's own cell is latent; an occupied one is the
        first hit at ``kappa = 0``, the thesis's ``f = 0`` (continuous kappa 0, a mean range of -1/2 cell)."""
        r = self.rays
        maps = torch.as_tensor(maps, dtype=torch.float64)
        if self.known_free.any() and (maps[..., self.known_free] != 0).any():
            raise ValueError("simulate_readings: a map occupies a cell pinned free (a cell holding a sensor)")
        f = self.first_hits(maps)  # ... x R
        lengths = self.lengths
        assert r.range_len is not None  # Rays.__post_init__ always fills it
        range_len = torch.from_numpy(np.maximum(r.range_len, r.lengths))
        T = self._entry_table()
        lam = float(self.prior.outside_occupancy())
        u = torch.rand(f.shape, generator=generator, dtype=torch.float64)
        if lam <= 0:
            extra = torch.full(f.shape, 1 << 40, dtype=torch.int64)
        elif lam >= 1:
            extra = torch.zeros(f.shape, dtype=torch.int64)
        else:  # free cells past the edge before the first occupied one: geometric
            extra = torch.floor(torch.log1p(-u) / math.log1p(-lam)).clamp(max=1 << 40).to(torch.int64)
        f = torch.where(f >= lengths, lengths + extra, f)
        none = f >= range_len
        fc = f.clamp(max=T.shape[1] - 1)
        Fm = torch.from_numpy(r.max_range_cells()).to(torch.float64)
        if self.sensor.continuous_range:
            F = Fm
            coord = torch.gather(T.expand(f.shape[:-1] + T.shape), -1, fc[..., None])[..., 0] + 0.5
            coord = torch.where(fc == 0, 0.0, coord)
        else:
            F = (range_len - 1).to(torch.float64)
            coord = fc.to(torch.float64)
        coord = torch.where(none, F + 1, coord)
        y, is_max = self.sensor.sample(coord, F.expand(coord.shape), generator=generator)
        if self.sensor.continuous_range:
            out = y - 0.5
        else:
            k = y.round().clamp(0, T.shape[1] - 1).to(torch.int64)
            out = torch.gather(T.expand(k.shape[:-1] + T.shape), -1, k[..., None])[..., 0]
        return torch.where(is_max, Fm.expand(out.shape), out)

    # ------------------------------------------------------------ maps
    def full_map(self, m: torch.Tensor) -> torch.Tensor:
        """Values of site ``"m"`` (``... x L`` latent cells, or already ``... x K``) -> maps ``... x K``."""
        return MapDistribution(self.prior, self.known_free).full_map(m)

    def check_maps(self, maps, what: str = "maps") -> torch.Tensor:
        """Validate maps ``... x K`` (or ``K``): the right number of cells, values 0/1 only, no NaN.

        Returns them as float64; raises ``ValueError`` naming ``what`` otherwise. Pinned cells are not
        checked here (:meth:`log_joint` gives ``-inf`` where one is occupied). Strings and other non-numeric
        values raise ``TypeError``."""
        return as_binary_maps(maps, self.num_cells, what)

    def _dense_rays(self) -> torch.Tensor:
        """``R x Lmax`` cell indices, padded with ``K`` (a dummy always-free column)."""
        if self._dense is None:
            r = self.rays
            Lmax = int(r.lengths.max())
            dense = np.full((r.num_rays, Lmax), self.num_cells, dtype=np.int64)
            dense[r.ray_of_entry, r.kappa] = r.cells
            self._dense = torch.from_numpy(dense)
        return self._dense

    def first_hits(self, maps: torch.Tensor, rays: torch.Tensor | None = None) -> torch.Tensor:
        """``f_n(m)``: kappa of the first occupied cell of every ray (``len_n`` if none).

        ``maps``: ``... x K`` (0/1); returns ``... x R`` (or ``... x len(rays)``) int64.
        """
        maps = torch.as_tensor(maps)
        batch = maps.shape[:-1]
        flat = maps.reshape(-1, self.num_cells) != 0
        flat = torch.cat([flat, torch.zeros(flat.shape[0], 1, dtype=torch.bool)], 1)
        dense = self._dense_rays() if rays is None else self._dense_rays()[rays]
        lengths = self.lengths if rays is None else self.lengths[rays]
        occ = flat[:, dense]  # B x R x Lmax
        first = torch.where(occ.any(-1), occ.to(torch.uint8).argmax(-1), lengths)
        return first.reshape(*batch, -1)

    def log_likelihood(self, maps: torch.Tensor) -> torch.Tensor:
        """``sum_n log p(z_n | f_n(m))`` for maps ``... x K`` -> ``...``."""
        f = self.first_hits(maps)
        R = self.rays.num_rays
        flat = f.reshape(-1, R)
        ll = self.loglik_table[torch.arange(R)[None, :], flat].sum(-1)
        return ll.reshape(f.shape[:-1])

    def log_joint(self, maps: torch.Tensor) -> torch.Tensor:
        """``log p(m) + log p(z | m)`` (``-inf`` where a pinned cell is occupied), ``... x K -> ...``.

        Raises ``ValueError`` for maps of the wrong length, values other than 0/1, or NaN from the prior."""
        maps = self.check_maps(maps, "log_joint's maps")
        pinned_ok = (maps[..., self.known_free] == 0).all(-1)
        lp = self.prior.log_prob(maps)
        if torch.isnan(torch.as_tensor(lp)).any():
            raise ValueError(f"{type(self.prior).__name__}.log_prob returned NaN")
        lj = lp + self.log_likelihood(maps)
        return torch.where(pinned_ok, lj, -math.inf)

    # ------------------------------------------------------------------ Pyro
    def model(self, readings=OBSERVED) -> torch.Tensor:
        """Pyro model: site ``"m"`` (the latent cells, event shape ``L``), the deterministic full map
        ``"map"`` (``K``) and the observed readings ``"z"`` (event shape ``R``).

        ``readings``: the value of ``"z"`` (default: the model's own readings, :attr:`readings`); ``None``
        samples them (prior / posterior predictive). Returns the full map.
        """
        m = pyro.sample("m", MapDistribution(self.prior, self.known_free))
        full = self.full_map(m)
        pyro.deterministic("map", full, event_dim=1)
        obs = self.readings if isinstance(readings, str) and readings == OBSERVED else readings
        pyro.sample("z", ReadingsDistribution(self, full), obs=obs)
        return full

    def model_per_cell(self) -> torch.Tensor:
        """Pyro model with one Bernoulli site ``"m_k"`` per latent cell, for exact enumeration.

        Each site is Bernoulli(1/2); the prior enters as a factor ``log p(m) + L log 2``, so any prior works.
        """
        K, L = self.num_cells, len(self.latent)
        cells = []
        for i in range(L):
            cells.append(
                pyro.sample(
                    f"m_{int(self.latent[i])}",
                    dist.Bernoulli(torch.tensor(0.5, dtype=torch.float64)),
                    infer={"enumerate": "parallel"},
                )
            )
        shape = torch.broadcast_shapes(*(c.shape for c in cells)) if cells else torch.Size()
        maps = torch.zeros(shape + (K,), dtype=torch.float64)
        for i, c in enumerate(cells):
            maps[..., int(self.latent[i])] = c.expand(shape)
        pyro.factor("prior", self.prior.log_prob(maps) + L * math.log(2.0))
        pyro.factor("z", self.log_likelihood(maps))
        return maps


def entry_table(rays: Rays) -> torch.Tensor:
    """``R x W`` float64 entry distances (cells) of every cell of every ray up to max range, past the grid edge
    included (``+inf`` padding, ``W`` the longest ray's cells); entry 0 (the sensor's cell) is 0."""
    r = rays
    assert r.range_len is not None  # Rays.__post_init__ always fills it
    range_len = np.maximum(r.range_len, r.lengths)
    T = np.full((r.num_rays, int(range_len.max())), np.inf)
    T[r.ray_of_entry, r.kappa] = r.t_enter
    cut = np.flatnonzero(range_len > r.lengths)
    if len(cut):
        off, t = r.entries_beyond_edge(cut)
        n = np.diff(off)
        T[np.repeat(cut, n), np.repeat(r.lengths[cut], n) + np.arange(len(t)) - np.repeat(off[:-1], n)] = t
    T[:, 0] = 0.0
    return torch.from_numpy(T)


def range_to_kappa(entries: torch.Tensor, ranges: torch.Tensor) -> torch.Tensor:
    """The kappa of readings (``... x R`` ranges in cells) on rays with entry distances ``entries``
    (:func:`entry_table`, ``R x W``), by the range convention of :mod:`ogm_ppl.raycast`: the cell whose entry
    distance is nearest; a tie goes to the nearer cell, as the ray caster does. A ray's kappa depends on its
    own row only (the ``+inf`` padding never counts), so rays cast apart get the kappa they get together."""
    mid = (entries[:, :-1] + entries[:, 1:]) / 2  # R x (W - 1), inf padding
    ranges = torch.as_tensor(ranges, dtype=torch.float64)
    return (mid < ranges[..., None]).sum(-1)
