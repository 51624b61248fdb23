r"""A prior raised to a power: ``p~(m)^beta`` (tempering, Geyer 1991), for parallel tempering's hot chains and for
priors whose coupling is too strong to predict unseen space well (a calibrated exponent, :mod:`~ogm_ppl.priors.named`'s
``@cal``).

Every log-potential is multiplied by ``beta``: ``log_prob``, ``log_prob_patch``, ``cell_log_odds`` and the compiled
bundle (``bundle.tempered(beta)``, the same bundle type, so every compiled kernel samples the tempered prior
unchanged). ``-inf`` (a configuration the prior forbids) stays ``-inf``: ``beta = 0`` is the uniform distribution over
the prior's support, ``0 < beta < 1`` flattens the prior towards it, ``beta = 1`` is the prior itself. For an MRF
(Section 5.2.1) ``beta`` scales the unary terms and ``log psi``; for a tile table (Sections 5.2.2, 5.2.3)
``phi(a) -> phi(a)^beta`` per tile, unnormalised.
"""

from __future__ import annotations

import math

import torch

from ogm_ppl.priors.base import MapPrior
from ogm_ppl.priors.transformed import TransformedPrior

__all__ = ["TemperedPrior"]


def _check_exponent(beta, what: str) -> float:
    b = float(beta)
    if not (math.isfinite(b) and b >= 0.0):
        raise ValueError(f"{what} must be finite and >= 0, got {beta!r}")
    return b


def _scale_log(x: torch.Tensor, beta: float) -> torch.Tensor:
    """``beta * x`` where ``x`` is finite; ``+-inf`` kept (so ``beta = 0`` keeps the support)."""
    return torch.where(torch.isfinite(x), x * beta, x)


class TemperedPrior(TransformedPrior):
    r"""``p~(m)^beta`` of a prior ``base``: ``log_prob``, ``log_prob_patch`` and ``cell_log_odds`` times
    ``beta`` (``-inf`` kept; ``beta = 0``: uniform over the support), ``compiled()`` the bundle's
    ``tempered(beta)``. ``outside_occupancy`` is the base prior's (it only enters the likelihood table).
    ``log_prob`` is unnormalised unless ``beta = 1`` (normalisers never matter to the samplers)."""

    BUNDLE_METHOD = "tempered"
    WHAT = "tempered"

    def __init__(self, base: MapPrior, beta: float) -> None:
        b = _check_exponent(beta, "beta")
        super().__init__(base, b, normalised=b == 1.0)  # normalised only at beta = 1 (and when the base is)
        self.beta = b

    def __repr__(self) -> str:
        return f"TemperedPrior({self.base!r}, beta={self.beta:g})"

    def log_prob(self, maps: torch.Tensor) -> torch.Tensor:
        return _scale_log(torch.as_tensor(self.base.log_prob(maps), dtype=torch.float64), self.beta)

    def log_prob_patch(self, maps: torch.Tensor, cells: torch.Tensor, configs: torch.Tensor) -> torch.Tensor:
        lp = torch.as_tensor(self.base.log_prob_patch(maps, cells, configs), dtype=torch.float64)
        return _scale_log(lp, self.beta)

    def cell_log_odds(self) -> torch.Tensor | None:
        lo = self.base.cell_log_odds()
        return None if lo is None else _scale_log(torch.as_tensor(lo, dtype=torch.float64), self.beta)

    def sample(self, sample_shape=(), generator: torch.Generator | None = None, num_sweeps: int = 100):
        """Maps from ``p~^beta``: the base prior's draws at ``beta = 1``; independent cells exactly;
        otherwise ``num_sweeps`` single-cell Gibbs sweeps of the tempered bundle from uniform noise."""
        if self.beta == 1.0:
            return self.base.sample(sample_shape, generator=generator)
        return self._draws(sample_shape, generator, num_sweeps)
