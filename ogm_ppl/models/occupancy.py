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
"""

from __future__ import annotations

import math

import numpy as np
import pyro
import pyro.distributions as dist
import torch
from pyro.distributions.torch_distribution import TorchDistribution
from torch.distributions import constraints

from ..raycast import Rays
from ..sensors import SensorModel

__all__ = ["OccupancyModel", "MapDistribution"]


class MapDistribution(TorchDistribution):
    """A Pyro distribution over whole binary maps (event shape ``K``) defined by a :class:`MapPrior`."""

    arg_constraints: dict = {}
    support = constraints.independent(constraints.boolean, 1)
    has_enumerate_support = False

    def __init__(self, prior, validate_args=None):
        self.prior = prior
        super().__init__(torch.Size(), torch.Size([prior.num_cells]), validate_args=validate_args)

    def sample(self, sample_shape=torch.Size()):
        return self.prior.sample(sample_shape)

    def log_prob(self, value):
        return self.prior.log_prob(value)


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
        if rays.grid != grid:
            raise ValueError("rays were cast on a different grid")
        if rays.num_rays == 0:
            raise ValueError("OccupancyModel needs at least one ray (the ray set is empty)")
        if prior.num_cells != grid.num_cells:
            raise ValueError(f"prior has {prior.num_cells} cells, the grid {grid.num_cells}")
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

    @property
    def num_cells(self) -> int:
        return self.grid.num_cells

    def _loglik_table(self) -> torch.Tensor:
        r = self.rays
        lengths = torch.from_numpy(r.lengths)
        range_len = torch.from_numpy(np.maximum(r.range_len, r.lengths))
        R, W = r.num_rays, int(lengths.max()) + 1
        is_max = torch.from_numpy(r.is_max.copy())
        bad = (torch.from_numpy(r.z) < 0) & ~is_max
        if bad.any():
            raise ValueError(f"reading of ray {int(bad.nonzero()[0, 0])} lies before its ray")
        col = torch.arange(W, dtype=torch.float64)[None, :]
        none_col = col == lengths[:, None]
        if self.sensor.continuous_range:  # continuous kappa t + 1/2 (ogm_ppl.sensors)
            z = torch.from_numpy(r.range_cells).to(torch.float64) + 0.5
            F = torch.from_numpy(r.max_range_cells()).to(torch.float64)
            t = torch.zeros(R, W, dtype=torch.float64)
            t[torch.from_numpy(r.ray_of_entry), torch.from_numpy(r.kappa)] = torch.from_numpy(r.t_enter).double()
            t[:, 0] = -0.5  # the sensor's own cell sits at kappa_c = 0 (ogm_ppl.sensors)
            f = torch.where(none_col, F[:, None] + 1, t + 0.5)
        else:
            z = torch.from_numpy(r.z).to(torch.float64)
            F = (range_len - 1).to(torch.float64)  # the sensor's last kappa, beyond the grid edge if cut
            f = torch.where(none_col, F[:, None] + 1, col)
        table = self.sensor.log_prob(z[:, None].expand(-1, W), f, F[:, None], is_max[:, None].expand(-1, W))
        table = table.to(torch.float64)
        cut = torch.nonzero(range_len > lengths).flatten()
        if len(cut):
            none = self._beyond_edge(cut, z[cut], F[cut], is_max[cut], lengths[cut], range_len[cut])
            table[cut, lengths[cut]] = none
        table = torch.where(col <= lengths[:, None], table, -math.inf)
        if torch.isnan(table).any():
            raise ValueError("the sensor model returned NaN log-likelihoods")
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
        """``log p(m) + log p(z | m)`` (``-inf`` where a pinned cell is occupied), ``... x K -> ...``."""
        maps = torch.as_tensor(maps, dtype=torch.float64)
        pinned_ok = (maps[..., self.known_free] == 0).all(-1)
        lj = self.prior.log_prob(maps) + self.log_likelihood(maps)
        return torch.where(pinned_ok, lj, -math.inf)

    # ------------------------------------------------------------------ Pyro
    def model(self) -> torch.Tensor:
        """Pyro model: one site ``"m"`` (the whole map, event shape ``K``) and the readings' factor."""
        m = pyro.sample("m", MapDistribution(self.prior))
        pinned_ok = (m[..., self.known_free] == 0).all(-1)
        ll = torch.where(pinned_ok, self.log_likelihood(m), -math.inf)
        pyro.factor("z", ll)
        return m

    def model_per_cell(self) -> torch.Tensor:
        """Pyro model with one Bernoulli site ``"m_k"`` per latent cell, for exact enumeration.

        Each site is Bernoulli(1/2); the prior enters as a factor ``log p(m) + L log 2``, so any prior works.
        """
        K, L = self.num_cells, len(self.latent)
        cells = []
        for i in range(L):
            cells.append(pyro.sample(f"m_{int(self.latent[i])}", dist.Bernoulli(torch.tensor(0.5, dtype=torch.float64)),
                                     infer={"enumerate": "parallel"}))  # fmt: skip
        shape = torch.broadcast_shapes(*(c.shape for c in cells)) if cells else torch.Size()
        maps = torch.zeros(shape + (K,), dtype=torch.float64)
        for i, c in enumerate(cells):
            maps[..., int(self.latent[i])] = c.expand(shape)
        pyro.factor("prior", self.prior.log_prob(maps) + L * math.log(2.0))
        pyro.factor("z", self.log_likelihood(maps))
        return maps
