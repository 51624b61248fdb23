r"""Pairwise priors on a neighbourhood stencil, and the higher-order MRF of Section 5.2.1.

:class:`StencilPrior` is the documented middle way from a researcher's idea to the compiled Gibbs path:
describe the prior by unary weights and pairwise weights per neighbour offset,

.. math:: \log p(m) = \sum_k m_k \Big(h_k + \sum_{d:\,k+d \in G} a_d\Big)
          + \tfrac12 \sum_k \sum_{d:\,k+d \in G} J_d\, m_k m_{k+d} - \log Z,

and every kernel (cell and patch Gibbs, ICM) reads the local conditional
``l(m_k | m_-k) = h_k + sum_{d: k+d in G} (a_d + J_d m_{k+d})`` from arrays, at the cost of one
stencil per update. Any symmetric pairwise binary MRF can be written this way.

:class:`MRFPrior` is the thesis's symmetric MRF: edge weight 1 between equal neighbours and ``psi``
between different ones, times the cell prior ``lambda``, so that

.. math:: l(m_k \mid \text{neighbours}) = l(\lambda) + (n_0 - n_1) \log \psi,

(``n0`` / ``n1`` free / occupied neighbours in the grid). Order 0: independent cells; order 1: 4-connected
in 2D, 2-connected in 1D; order 2: 8-connected in 2D, 4-connected (offsets +-1, +-2) in 1D (Fig. 5.6).
``log_prob`` is exact up to the log partition function ``log Z`` (not computed: intractable beyond small
maps; :meth:`~ogm_ppl.priors.local.LocalMapPrior.log_normaliser` enumerates it for tiny ones). Gibbs and
ICM never need it.
"""

from __future__ import annotations

import math

import numpy as np
import torch

from ogm_ppl.priors.compiled import stencil
from ogm_ppl.priors.local import LocalMapPrior, grid_shape

__all__ = ["StencilPrior", "MRFPrior"]


class StencilPrior(LocalMapPrior):
    """A pairwise binary field on a stencil (unary + pairwise weights), on the compiled path.

    Args:
        shape: grid shape, ``(K,)`` or ``(rows, cols)`` (or a :class:`~ogm_ppl.Grid`).
        unary: ``h``, a scalar or ``K`` log-odds weights.
        offsets: ``D x 2`` neighbour offsets ``(dr, dc)`` (1D: ``(0, dc)`` or plain ints). The stencil is
            made symmetric: ``-d`` is added with the weights of ``d`` when absent.
        coupling: ``J_d``, a scalar or ``D`` values (``J_d = J_{-d}`` is required).
        bias: ``a_d``, a scalar or ``D`` values: added to the log-odds of a cell per neighbour inside the grid.
        outside: ``lambda_out`` of :meth:`outside_occupancy` (the occupancy of cells beyond the grid edge);
            ``None``: the field's own cell marginal away from the edges.

    >>> p = StencilPrior((2, 3), unary=-1.0, offsets=[(0, 1), (1, 0)], coupling=2.0)
    >>> round(float(p.log_prob(torch.tensor([1., 1., 0., 0., 0., 0.]))), 4)  # 2 h + J
    0.0
    """

    normalised = False

    def __init__(self, shape, unary=0.0, offsets=(), coupling=0.0, bias=0.0, outside: float | None = None) -> None:
        if outside is not None and not 0.0 <= float(outside) <= 1.0:
            raise ValueError(f"{type(self).__name__}.outside must lie in [0, 1], got {outside}")
        self._outside = None if outside is None else float(outside)
        self.rows, self.cols, self.ndim = grid_shape(shape)
        self.shape = (self.cols,) if self.ndim == 1 else (self.rows, self.cols)
        self.num_cells = K = self.rows * self.cols
        h = np.broadcast_to(np.asarray(unary, np.float64), (K,)).copy()
        off = np.asarray(offsets, dtype=np.int64)
        if off.ndim == 1:
            off = np.stack([np.zeros(len(off), np.int64), off], 1) if off.size else off.reshape(0, 2)
        if off.ndim != 2 or off.shape[1] != 2:
            raise ValueError(f"offsets must be D x 2 (dr, dc), got shape {off.shape}")
        if (off == 0).all(1).any():
            raise ValueError("offset (0, 0) is not a neighbour")
        if self.ndim == 1 and (off[:, 0] != 0).any():
            raise ValueError("a 1D grid takes offsets along the row only")
        J = np.broadcast_to(np.asarray(coupling, np.float64), (len(off),)).copy()
        a = np.broadcast_to(np.asarray(bias, np.float64), (len(off),)).copy()
        if not (np.isfinite(h).all() and np.isfinite(J).all() and np.isfinite(a).all()):
            raise ValueError("StencilPrior weights must be finite")
        table: dict[tuple[int, int], tuple[float, float]] = {}
        for (dr, dc), j, b in zip(off.tolist(), J, a):
            if (dr, dc) in table:
                raise ValueError(f"offset {(dr, dc)} given twice")
            table[(dr, dc)] = (float(j), float(b))
        for (dr, dc), (j, b) in list(table.items()):
            other = table.get((-dr, -dc))
            if other is None:
                table[(-dr, -dc)] = (j, b)
            elif other[0] != j:
                raise ValueError(f"coupling of {(dr, dc)} and {(-dr, -dc)} differ: J_d = J_-d is required")
        keys = sorted(table)
        self.offsets = np.array(keys, dtype=np.int64).reshape(-1, 2)
        self.coupling = np.array([table[k][0] for k in keys], np.float64)
        self.bias = np.array([table[k][1] for k in keys], np.float64)
        self.unary = h
        self._compiled = stencil(
            self.rows, self.cols, h, self.offsets[:, 0], self.offsets[:, 1], self.bias, self.coupling
        )
        # per-cell sum of a_d over neighbours inside the grid
        r, c = np.divmod(np.arange(K), self.cols)
        nb = np.zeros(K)
        for (dr, dc), b in zip(self.offsets, self.bias):
            nb += b * ((r + dr >= 0) & (r + dr < self.rows) & (c + dc >= 0) & (c + dc < self.cols))
        self._lin = torch.from_numpy(h + nb)

    def __repr__(self) -> str:
        return f"{type(self).__name__}(shape={self.shape}, offsets={len(self.offsets)})"

    def outside_occupancy(self) -> float:
        """``outside`` if given, else the field's cell marginal ``P(m_k = 1)`` away from the edges: with no
        coupling the mean of ``sigmoid(h_k + sum_d a_d)`` (independent cells), otherwise estimated once
        (seeded, cached) by compiled prior Gibbs chains on a ``48 x 48`` grid (``48`` cells in 1D) with the mean
        unary weight, as :meth:`MRFPrior.outside_occupancy`."""
        if self._outside is None:
            interior = self.unary + self.bias.sum()
            if not self.coupling.any():
                self._outside = float(np.mean(1.0 / (1.0 + np.exp(-interior))))
            else:
                shape = (48, 48) if self.ndim == 2 else (48,)
                field = StencilPrior(shape, float(self.unary.mean()), self.offsets, self.coupling, self.bias)
                self._outside = _estimate_marginal(field.compiled(), shape)
        return self._outside

    def log_prob(self, maps):
        """``log p~(m)`` (without ``-log Z``) for ``... x K`` maps -> ``...``."""
        maps = torch.as_tensor(maps, dtype=torch.float64)
        batch = maps.shape[:-1]
        x = maps.reshape(-1, self.rows, self.cols)
        out = (x.reshape(x.shape[0], -1) * self._lin).sum(-1)
        R, C = self.rows, self.cols
        for (dr, dc), j in zip(self.offsets.tolist(), self.coupling):
            if j == 0 or abs(dr) >= R or abs(dc) >= C:
                continue
            a = x[:, max(0, -dr) : R - max(0, dr), max(0, -dc) : C - max(0, dc)]
            b = x[:, max(0, dr) : R - max(0, -dr), max(0, dc) : C - max(0, -dc)]
            out = out + 0.5 * j * (a * b).sum((-2, -1))
        return out.reshape(batch)

    def sample(self, sample_shape=(), generator=None, num_sweeps: int = 100):
        """Maps drawn by ``num_sweeps`` single-cell Gibbs sweeps on the prior alone (from uniform noise)."""
        return self._gibbs_sample(sample_shape, generator, num_sweeps)


def _mrf_offsets(order: int, ndim: int) -> list[tuple[int, int]]:
    if order == 0:
        return []
    if ndim == 1:
        return [(0, d) for d in range(1, order + 1)]
    if order == 1:
        return [(0, 1), (1, 0)]
    if order == 2:
        return [(0, 1), (1, 0), (1, 1), (1, -1)]
    raise ValueError(f"MRF order must be 0, 1 or 2 in 2D, got {order}")


class MRFPrior(StencilPrior):
    r"""The symmetric higher-order MRF of Section 5.2.1 (Fig. 5.6, 5.7, 5.8).

    .. math:: p(m) = \frac{1}{Z} \prod_k \lambda^{m_k} (1 - \lambda)^{1 - m_k}
              \prod_{(j, k) \in E} \psi^{[m_j \ne m_k]}

    Args:
        shape: grid shape ``(K,)`` or ``(rows, cols)``.
        order: 0 (independent), 1 (4-connected in 2D, 2 in 1D), 2 (8-connected in 2D, 4 in 1D); in 1D any
            order ``n`` connects the ``2 n`` nearest cells.
        psi: edge weight between unequal neighbours, ``0 < psi <= 1`` (1: no correlation).
        cell_prior: ``lambda``, the cell prior (scalar or ``K``).
        outside: ``lambda_out`` of :meth:`outside_occupancy` (the occupancy of cells beyond the grid edge);
            ``None``: the MRF's own cell marginal, estimated by prior Gibbs sampling. The named MRFs
            (``mrf:CORPUS``) pass the corpus's occupied share, the marginal their fit aims at: a strongly
            coupled fit is in an ordered phase whose sampled marginal is near 0 or 1.

    >>> p = MRFPrior((3, 3), order=1, psi=0.5)
    >>> float(p.compiled().coupling[0]) == -2 * math.log(0.5)
    True
    """

    def __init__(self, shape, order: int = 1, psi: float = 0.5, cell_prior=0.5, outside: float | None = None) -> None:
        if not 0.0 < float(psi) <= 1.0:
            raise ValueError(f"MRFPrior.psi must lie in (0, 1], got {psi}")
        lam = np.asarray(cell_prior, np.float64)
        if np.isnan(lam).any() or (lam <= 0).any() or (lam >= 1).any():
            raise ValueError(f"MRFPrior.cell_prior must lie in (0, 1), got {cell_prior!r}")
        if int(order) != order or order < 0:
            raise ValueError(f"MRF order must be a non-negative integer, got {order}")
        _, _, ndim = grid_shape(shape)
        lp = math.log(float(psi))
        super().__init__(shape, np.log(lam) - np.log1p(-lam), _mrf_offsets(int(order), ndim), -2.0 * lp, lp, outside)
        self.order, self.psi, self.cell_prior = int(order), float(psi), lam
        self.mean_occupancy = float(lam.mean())

    def __repr__(self) -> str:
        return f"MRFPrior(shape={self.shape}, order={self.order}, psi={self.psi:.4g})"

    def outside_occupancy(self) -> float:
        """``outside`` if given, else the MRF's cell marginal ``P(m_k = 1)`` away from the edges: ``lambda``
        itself for an independent MRF (``psi = 1`` or order 0); otherwise estimated once (seeded, cached) by
        compiled prior Gibbs chains on a ``48 x 48`` grid (``48`` cells in 1D) with the mean cell prior:
        8 chains from uniform noise, 300 sweeps, the centre cells of the last 100 sweeps (every 10th).
        (``mean_occupancy``, the conditional ``lambda``, is not the marginal once ``psi < 1`` and
        ``lambda != 0.5``.)"""
        lam = float(self.cell_prior.mean())
        if self._outside is None and (self.psi == 1.0 or self.order == 0):
            return lam
        if self._outside is None:
            shape = (48, 48) if len(self.shape) == 2 else (48,)
            self._outside = _estimate_marginal(MRFPrior(shape, self.order, self.psi, lam).compiled(), shape)
        return self._outside


def _estimate_marginal(bundle, shape: tuple[int, ...], chains: int = 8) -> float:
    """``P(m_k = 1)`` away from the edges of the compiled prior ``bundle`` on a grid of ``shape`` by compiled
    prior Gibbs (see :meth:`MRFPrior.outside_occupancy`)."""
    from ogm_ppl.priors.compiled import prior_gibbs_sweeps

    ndim = len(shape)
    rng = np.random.default_rng(0)
    maps = np.ascontiguousarray(rng.random((chains, int(np.prod(shape)))) < 0.5, dtype=np.uint8)
    prior_gibbs_sweeps(bundle, maps, 200, 0)
    edge = 8 if ndim == 2 else 4
    tot = 0.0
    for i in range(10):
        prior_gibbs_sweeps(bundle, maps, 10, 1 + i)
        g = maps.reshape((chains, *shape))
        g = g[:, edge:-edge, edge:-edge] if ndim == 2 else g[:, edge:-edge]
        tot += float(g.mean())
    return tot / 10
