r"""A prior with a unary bias: ``p~(m) exp(h sum_k m_k)``, a log-odds shift ``h`` on every cell.

Far from any reading a prior's marginals are its own, and a prior whose tables are products of conditionals
(the border prior of Section 5.2.3, the 1-given-8 table) is not fitted to its corpus as a joint: the occupied
share of its own draws need not be the corpus's (:func:`ogm_ppl.learn.bias.occupancy_trace` measures it). The bias is
the one-parameter maximum-entropy correction: among the priors ``p~(m) exp(h sum_k m_k)`` the one whose draws fill
the share ``lambda`` of the corpus satisfies the moment condition ``E_h[mean_k m_k] = lambda``, which the fitted
pattern field's unary bias already meets (:func:`~ogm_ppl.priors.learn_field.fit_tempered`); ``ogm-ppl fit-prior bias``
(:func:`ogm_ppl.learn.fit_bias`) fits ``h`` for the other priors.

Every log-potential changes by ``h`` per occupied cell: ``log_prob`` gains ``h sum_k m_k``, ``log_prob_patch``
``h sum_{k in C} c_k``, the cell log-odds ``h``, and the compiled bundle is ``bundle.biased(h)`` (the same bundle
type: every compiled kernel samples the biased prior unchanged). ``-inf`` (a configuration the prior forbids)
stays ``-inf``. A tile table adds ``h`` times the occupied cells of each tile's own cells to its factors (the
tiles partition the grid, so the factors sum to ``h sum_k m_k`` plus a constant from the cells off the grid).
"""

from __future__ import annotations

import math

import torch

from ogm_ppl.priors.base import MapPrior
from ogm_ppl.priors.transformed import TransformedPrior

__all__ = ["BiasedPrior"]


def _shift(x: torch.Tensor, add: torch.Tensor) -> torch.Tensor:
    """``x + add`` where ``x`` is finite; ``+-inf`` kept."""
    return torch.where(torch.isfinite(x), x + add, x)


class BiasedPrior(TransformedPrior):
    r"""``p~(m) exp(h sum_k m_k)`` of a prior ``base`` (module docstring): ``log_prob`` plus ``h sum_k m_k``,
    ``log_prob_patch`` plus ``h`` times each configuration's occupied cells, ``cell_log_odds`` plus ``h``,
    ``compiled()`` the bundle's ``biased(h)``. ``outside_occupancy`` is the base prior's. ``log_prob`` is
    unnormalised unless ``h = 0``.

    Args:
        base: any prior (a :class:`~ogm_ppl.priors.TemperedPrior` too: bias after tempering).
        bias: ``h``, finite (``> 0`` fills more cells, ``< 0`` fewer).

    >>> from ogm_ppl.priors import IndependentPrior
    >>> p = BiasedPrior(IndependentPrior(0.5, 3), math.log(3.0))  # odds 1 -> 3
    >>> round(float(torch.sigmoid(p.cell_log_odds())[0]), 6)
    0.75
    """

    BUNDLE_METHOD = "biased"
    WHAT = "biased"

    def __init__(self, base: MapPrior, bias: float) -> None:
        h = float(bias)
        if not math.isfinite(h):
            raise ValueError(f"bias must be finite, got {bias!r}")
        super().__init__(base, h, normalised=h == 0.0)
        self.bias = h

    def __repr__(self) -> str:
        return f"BiasedPrior({self.base!r}, bias={self.bias:g})"

    def log_prob(self, maps: torch.Tensor) -> torch.Tensor:
        maps = torch.as_tensor(maps, dtype=torch.float64)
        return _shift(torch.as_tensor(self.base.log_prob(maps), dtype=torch.float64), self.bias * maps.sum(-1))

    def log_prob_patch(self, maps: torch.Tensor, cells: torch.Tensor, configs: torch.Tensor) -> torch.Tensor:
        lp = torch.as_tensor(self.base.log_prob_patch(maps, cells, configs), dtype=torch.float64)
        return _shift(lp, self.bias * torch.as_tensor(configs, dtype=torch.float64).sum(-1))

    def cell_log_odds(self) -> torch.Tensor | None:
        lo = self.base.cell_log_odds()
        return None if lo is None else _shift(torch.as_tensor(lo, dtype=torch.float64), torch.tensor(self.bias))

    def sample(self, sample_shape=(), generator: torch.Generator | None = None, num_sweeps: int = 100):
        """Maps from the biased prior: the base prior's draws at ``h = 0``; independent cells exactly; otherwise
        ``num_sweeps`` single-cell Gibbs sweeps of the biased bundle from uniform noise."""
        if self.bias == 0.0:
            return self.base.sample(sample_shape, generator=generator)
        return self._draws(sample_shape, generator, num_sweeps)
