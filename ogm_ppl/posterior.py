r"""Posterior summaries shared by every inference result (Sections 2.3, 2.6, 4.2.3).

* marginals ``p(m_k = 1 | z)`` (Eq. 2.6);
* the first-occupied-cell distribution of a ray, ``p(f = k | z) = p(m_{<k} = 0, m_k = 1 | z)``
  (Eq. 4.6), with the last entry for "no occupied cell on the ray";
* pairwise joints and the mutual-information matrix
  ``MI(m_j, m_k) = sum p(m_j, m_k) log p(m_j, m_k) / (p(m_j) p(m_k))`` (Section 2.6; the diagonal holds
  each cell's entropy);
* ``P(all cells of a path are free | z)``, exact, and its cell-independence approximation.

:class:`WeightedMaps` covers any posterior given as weighted maps (brute-force enumeration, or samples with
equal weights); :class:`ChainPosterior1D` the closed forms of the pose-constrained 1D solutions. Every
statistic is computed in float64 and checked for NaN.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from functools import cached_property
from typing import TYPE_CHECKING

import torch

if TYPE_CHECKING:
    from ogm_ppl.models.occupancy import OccupancyModel

__all__ = [
    "MapPosterior",
    "WeightedMaps",
    "ChainPosterior1D",
    "mutual_information_from_joint",
    "first_hit_independent",
]


def _no_nan(t: torch.Tensor, what: str) -> torch.Tensor:
    if torch.isnan(t).any():
        raise FloatingPointError(f"{what} contains NaN")
    return t


def mutual_information_from_joint(p: torch.Tensor, p11: torch.Tensor) -> torch.Tensor:
    """MI matrix from marginals ``p`` (``C``) and pairwise ``P(m_i = 1, m_j = 1)`` (``C x C``)."""
    pi, pj = p[:, None], p[None, :]
    joint = torch.stack([1 - pi - pj + p11, pj - p11, pi - p11, p11]).clamp(min=0.0)  # 00, 01, 10, 11
    prod = torch.stack([(1 - pi) * (1 - pj), (1 - pi) * pj, pi * (1 - pj), pi * pj]).expand_as(joint)
    ok = (joint > 0) & (prod > 0)  # joint <= each marginal, so prod = 0 forces joint = 0 (up to rounding)
    terms = torch.where(ok, joint * (torch.log(joint) - torch.log(prod)), torch.zeros_like(joint))
    mi = terms.sum(0).clamp(min=0.0)
    return _no_nan(0.5 * (mi + mi.T), "mutual information")


def first_hit_independent(marginals_along_ray: torch.Tensor) -> torch.Tensor:
    r"""``p(f = k) ~= p(m_k) prod_{i<k} (1 - p(m_i))`` (Eq. 4.7), with "none" last (``L + 1``)."""
    p = torch.as_tensor(marginals_along_ray, dtype=torch.float64)
    free_before = torch.cumprod(torch.cat([p.new_ones(1), 1 - p]), 0)
    return torch.cat([p * free_before[:-1], free_before[-1:]])


class MapPosterior:
    """Interface of posterior results over the maps of an :class:`~ogm_ppl.OccupancyModel`."""

    model: OccupancyModel  # set by every subclass's __init__

    @property
    def marginals(self) -> torch.Tensor:  # pragma: no cover - interface
        """``p(m_k = 1 | z)``, ``K``."""
        raise NotImplementedError

    def pair_joint(self, cells=None) -> torch.Tensor:  # pragma: no cover - interface
        """``P(m_i = 1, m_j = 1 | z)`` for ``cells`` (default: all), ``C x C``."""
        raise NotImplementedError

    def first_hit(self, ray: int = 0) -> torch.Tensor:  # pragma: no cover - interface
        """``p(f = kappa | z)`` along ``ray`` (Eq. 4.6), ``len + 1`` (last: no occupied cell)."""
        raise NotImplementedError

    def prob_free(self, cells) -> float:  # pragma: no cover - interface
        """``P(m_c = 0 for every c in cells | z)``, exact."""
        raise NotImplementedError

    def mutual_information(self, cells=None) -> torch.Tensor:
        """Mutual information between every pair of ``cells`` (default: all), ``C x C``, in nats."""
        idx = self._cells(cells)
        return mutual_information_from_joint(self.marginals[idx], self.pair_joint(idx))

    def prob_free_independent(self, cells) -> float:
        """``prod_c (1 - p(m_c = 1 | z))``: the path probability under cell independence."""
        idx = self._cells(cells)
        return float(torch.prod(1 - self.marginals[idx]))

    def first_hit_independent(self, ray: int = 0) -> torch.Tensor:
        """Eq. (4.7) along ``ray`` from this posterior's marginals."""
        r = self.model.rays
        return first_hit_independent(self.marginals[torch.from_numpy(r.ray(ray))])

    def _cells(self, cells) -> torch.Tensor:
        if cells is None:
            return torch.arange(self.model.num_cells)
        idx = torch.as_tensor(cells, dtype=torch.long).flatten()
        K = self.model.num_cells
        if idx.numel() and (idx.min() < 0 or idx.max() >= K):
            raise ValueError(f"cells must lie in 0..{K - 1}")
        return idx


class WeightedMaps(MapPosterior):
    """A posterior given as maps with probabilities, visited in chunks so memory stays bounded.

    Args:
        model: the :class:`~ogm_ppl.OccupancyModel`.
        chunks: a callable returning an iterator of ``(maps B x K float64, probs B)``; the probabilities
            over all chunks sum to one.
        num_maps: how many maps the chunks hold (for display).
    """

    log_probs: torch.Tensor  # normalised log-probability of every map (set by ``brute_force``)
    log_evidence: float  # log p(z) (set by ``brute_force``)

    def __init__(self, model, chunks: Callable[[], Iterator[tuple[torch.Tensor, torch.Tensor]]], num_maps: int) -> None:
        self.model = model
        self._chunk_fn = chunks
        self.num_maps = int(num_maps)

    @classmethod
    def from_samples(cls, model, samples: torch.Tensor, chunk: int = 4096) -> WeightedMaps:
        """Equal weights on ``S x K`` sampled maps (e.g. from MCMC)."""
        samples = torch.as_tensor(samples, dtype=torch.float64)
        if samples.dim() != 2 or samples.shape[1] != model.num_cells:
            raise ValueError(f"samples must be S x {model.num_cells}, got {tuple(samples.shape)}")
        S = samples.shape[0]
        if S == 0:
            raise ValueError("no samples")

        def chunks():
            for a in range(0, S, chunk):
                part = samples[a : a + chunk]
                yield part, torch.full((part.shape[0],), 1.0 / S, dtype=torch.float64)

        return cls(model, chunks, S)

    def chunks(self):
        return self._chunk_fn()

    @cached_property
    def marginals(self) -> torch.Tensor:
        acc = torch.zeros(self.model.num_cells, dtype=torch.float64)
        for maps, w in self.chunks():
            acc += w @ maps
        return _no_nan(acc.clamp(0.0, 1.0), "marginals")

    def pair_joint(self, cells=None) -> torch.Tensor:
        idx = self._cells(cells)
        acc = torch.zeros(len(idx), len(idx), dtype=torch.float64)
        for maps, w in self.chunks():
            m = maps[:, idx]
            acc += (m * w[:, None]).T @ m
        return _no_nan(acc, "pair joint")

    def first_hit(self, ray: int = 0) -> torch.Tensor:
        n = int(self.model.lengths[ray])
        acc = torch.zeros(n + 1, dtype=torch.float64)
        rays = torch.tensor([ray])
        for maps, w in self.chunks():
            f = self.model.first_hits(maps, rays)[:, 0]
            acc += torch.bincount(f, weights=w, minlength=n + 1)
        return _no_nan(acc, "first-hit distribution")

    def prob_free(self, cells) -> float:
        idx = self._cells(cells)
        total = 0.0
        for maps, w in self.chunks():
            total += float(w[(maps[:, idx] == 0).all(1)].sum())
        return total

    def mode(self) -> tuple[torch.Tensor, float]:
        """The most probable map (``K`` float 0/1; of several equally probable, the first visited) and its
        probability: under :func:`~ogm_ppl.inference.exact.brute_force` the MAP map, which hill-climbing
        (:func:`~ogm_ppl.inference.exact.map_estimate.map_estimate`) may miss."""
        best, p_best = None, -1.0
        for maps, w in self.chunks():
            i = int(torch.argmax(w))
            if float(w[i]) > p_best:
                best, p_best = maps[i].clone(), float(w[i])
        assert best is not None  # every posterior holds at least one map
        return best, p_best


class ChainPosterior1D(MapPosterior):
    r"""Posterior of a stationary 1D robot: a distribution over the first occupied cell of the common
    ray, with the cells behind it independent (Sections 2.3.1, 5.1).

    Args:
        model: the model (all rays share one cell sequence ``c_0..c_{n-1}``).
        log_pf: ``n + 1`` normalised log-probabilities of ``f = 0..n-1`` and "none".
        behind: ``n`` probabilities that a cell behind the first occupied one is occupied (the prior
            ``lambda_k`` for an independent prior; 1 for the data-driven prior).

    With ``C(i) = P(f < i)``: ``p(m_i) = P(f = i) + C(i) beta_i`` and, for ``i < j``,
    ``P(m_i = 1, m_j = 1) = P(f = i) beta_j + C(i) beta_i beta_j``.
    """

    log_evidence: float  # log p(z) (set by ``pose_constrained_1d``)

    def __init__(self, model, log_pf: torch.Tensor, behind: torch.Tensor) -> None:
        self.model = model
        self.cells = torch.from_numpy(model.rays.ray(0).copy())
        self.log_pf = _no_nan(log_pf, "log p(f | z)")
        self.pf = torch.exp(log_pf)
        self.behind = behind.to(torch.float64)
        self._pos = torch.full((model.num_cells,), -1, dtype=torch.long)
        self._pos[self.cells] = torch.arange(len(self.cells))

    @cached_property
    def _before(self) -> torch.Tensor:
        """``C(i) = P(f < i)`` for ``i = 0..n-1``."""
        return torch.cumsum(torch.cat([self.pf.new_zeros(1), self.pf[:-2]]), 0)

    @cached_property
    def marginals(self) -> torch.Tensor:
        n = len(self.cells)
        on_ray = self.pf[:n] + self._before * self.behind
        out = torch.zeros(self.model.num_cells, dtype=torch.float64)
        out[self.cells] = on_ray
        return _no_nan(out.clamp(0.0, 1.0), "marginals")

    def _positions(self, idx: torch.Tensor) -> torch.Tensor:
        pos = self._pos[idx]
        if (pos < 0).any():
            raise ValueError("a requested cell is not on the robot's ray")
        return pos

    def pair_joint(self, cells=None) -> torch.Tensor:
        """``P(m_i = 1, m_j = 1 | z)``, ``C x C``, in the order of ``cells`` (default: every cell of the
        grid in cell order, as :func:`~ogm_ppl.inference.exact.posteriors.brute_force` returns it). Cells off the
        robot's ray are independent of the rest (no reading reaches them)."""
        idx = self._cells(cells)
        on = self._pos[idx] >= 0
        pos = self._pos[idx].clamp(min=0)
        pf, C, b = self.pf[pos], self._before[pos], self.behind[pos]
        pi, pj = pos[:, None], pos[None, :]
        first_lo = torch.where(pi < pj, pf[:, None] * b[None, :], pf[None, :] * b[:, None])
        joint = first_lo + torch.where(pi < pj, C[:, None], C[None, :]) * b[:, None] * b[None, :]
        m = self.marginals[idx]
        joint = torch.where(on[:, None] & on[None, :], joint, m[:, None] * m[None, :])
        same = idx[:, None] == idx[None, :]
        joint = torch.where(same, m[:, None].expand_as(joint), joint)
        return _no_nan(joint, "pair joint")

    def mutual_information(self, cells=None) -> torch.Tensor:
        """Mutual information between every pair of ``cells``, ``C x C`` in nats, in the order of ``cells``
        (default: every cell in cell order, as every other posterior returns it)."""
        idx = self._cells(cells)
        return mutual_information_from_joint(self.marginals[idx], self.pair_joint(idx))

    def first_hit(self, ray: int = 0) -> torch.Tensor:
        return self.pf.clone()

    def first_hit_independent(self, ray: int = 0) -> torch.Tensor:
        return first_hit_independent(self.marginals[self.cells])

    def prob_free(self, cells) -> float:
        idx = self._cells(cells)
        pos = self._positions(idx)
        n = len(self.cells)
        in_c = torch.zeros(n, dtype=torch.bool)
        in_c[pos] = True
        # P(all of C free) = sum_f P(f) [f not in C] prod_{c in C, c > f} (1 - beta_c) + P(none)
        log_free = torch.where(in_c, torch.log1p(-self.behind.clamp(max=1.0)), torch.zeros(n, dtype=torch.float64))
        after = torch.flip(torch.cumsum(torch.flip(log_free, [0]), 0), [0])  # sum over c >= f
        after_strict = torch.cat([after[1:], after.new_zeros(1)])
        terms = torch.where(in_c, torch.zeros(n, dtype=torch.float64), self.pf[:n] * torch.exp(after_strict))
        return float(terms.sum() + self.pf[n])
