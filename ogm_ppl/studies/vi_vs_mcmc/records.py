"""The settings, result records and scoring of the VI-against-MCMC comparison (:mod:`ogm_ppl.studies.vi_vs_mcmc`).

Every method is scored by the summed cell KL to the exact posterior over the latent cells,
``sum_k KL(p_k || q_k)`` with ``p_k = p(m_k = 1 | z)`` exact and ``q_k`` the estimate clamped to
``[EPS, 1 - EPS]`` (:func:`summed_kl`); an anytime method keeps the curve of that KL against seconds at the
budgets of :func:`budgets` (:class:`Record`).
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields
from typing import Any

import torch

from ogm_ppl.metrics import kl_divergence

__all__ = [
    "EPS",
    "PROBLEMS",
    "QUICK",
    "TARGET",
    "WALLS",
    "ComparisonSettingsError",
    "Record",
    "Settings",
    "budgets",
    "summed_kl",
]

#: estimates are clamped to ``[EPS, 1 - EPS]`` before the KL (a sampler's 0/1 frequencies)
EPS = 1e-9
#: the target accuracy: within 0.01 summed KL of exact
TARGET = 0.01
#: the wall datasets (:func:`~ogm_ppl.datasets.wall_datasets`): ``F`` cells of range, the wall at 60, sigma 3,
#: 1..10 readings
WALLS: dict[str, Any] = dict(F=75, wall=60, sigma=3.0, num_readings=(1, 10))
#: the problems, in the order of the full run
PROBLEMS: tuple[str, ...] = ("toy", "walls", "2d:independent", "2d:mrf8", "2d:patch3")


class ComparisonSettingsError(ValueError):
    """A :class:`Settings` field out of range; ``option`` names it, the message the limit."""

    def __init__(self, option: str, reason: str) -> None:
        super().__init__(f"{option}: {reason}")
        self.option, self.reason = option, reason


@dataclass(frozen=True)
class Settings:
    """Sizes of the run (the quick run: :data:`QUICK`) and the ``problems`` run (of :data:`PROBLEMS`).

    Raises :class:`ComparisonSettingsError` naming the first field out of range."""

    vi_steps: int = 600  # closed-form (ExactELBO) fits, 1D toy and 2D
    vi_steps_sampled: int = 300  # TraceGraph_ELBO / RWS fits, 1D toy and 2D
    particles_tracegraph: int = 128
    particles_rws: int = 256
    toy_gibbs_sweeps: int = 100_000  # cell Gibbs (one compiled call per checkpoint)
    gibbs_sweeps: int = 10_000  # patch Gibbs and 2D kernels (one Python call per sweep)
    walls: int = 1000
    folds: int = 5
    walls_gibbs_sweeps: int = 1000  # cell Gibbs on every dataset
    walls_patch_gibbs: int = 50  # datasets for patch Gibbs
    walls_patch_gibbs_sweeps: int = 300
    walls_vi_exact: int = 4  # datasets for the ExactELBO guides
    walls_vi_sampled: int = 2  # datasets for the sampled objectives
    walls_vi_steps: int = 1000
    walls_vi_steps_sampled: int = 100
    heldout: int = 1000  # fresh wall datasets (seed + 1) for the shipped artefacts
    delta_max_iter: int = 500
    problems: tuple[str, ...] = PROBLEMS

    def __post_init__(self) -> None:
        object.__setattr__(self, "problems", tuple(self.problems))
        for f in fields(self):
            v = getattr(self, f.name)
            lo = 0 if f.name in _MAY_BE_ZERO else 1
            if f.name != "problems" and (isinstance(v, bool) or not isinstance(v, int) or v < lo):
                raise ComparisonSettingsError(f.name, f"must be a whole number of at least {lo}, got {v!r}")
        if self.gibbs_sweeps < 3:
            raise ComparisonSettingsError(
                "gibbs_sweeps", f"must be at least 3 (guided Gibbs runs a third), got {self.gibbs_sweeps}"
            )
        if self.folds > self.walls:
            raise ComparisonSettingsError("folds", f"must be at most walls ({self.walls}), got {self.folds}")
        unknown = [p for p in self.problems if p not in PROBLEMS]
        if unknown or not self.problems or len(set(self.problems)) != len(self.problems):
            raise ComparisonSettingsError(
                "problems", f"give distinct problems of {', '.join(PROBLEMS)}, got {', '.join(self.problems) or 'none'}"
            )


#: the fields that may be 0 (the datasets the slower methods run on)
_MAY_BE_ZERO = ("walls_patch_gibbs", "walls_vi_exact", "walls_vi_sampled")


QUICK = Settings(
    vi_steps=100,
    vi_steps_sampled=30,
    particles_tracegraph=32,
    particles_rws=64,
    toy_gibbs_sweeps=10_000,
    gibbs_sweeps=1000,
    walls=50,
    folds=2,
    walls_gibbs_sweeps=300,
    walls_patch_gibbs=5,
    walls_patch_gibbs_sweeps=100,
    walls_vi_exact=2,
    walls_vi_sampled=1,
    walls_vi_steps=60,
    walls_vi_steps_sampled=20,
    heldout=50,
    delta_max_iter=100,
)


def budgets(total: int, start: int = 10) -> list[int]:
    """Checkpoints 10, 30, 100, 300, ... up to ``total`` (``total`` always last).

    >>> budgets(600), budgets(5)
    ([10, 30, 100, 300, 600], [5])
    """
    out, b = [], start
    while b < total:
        out.append(b)
        b = b * 3 if str(b).startswith("1") else b * 10 // 3
    return [*out, int(total)]


def summed_kl(exact: torch.Tensor, q: torch.Tensor, latent: torch.Tensor) -> float:
    """Summed cell ``KL(exact || q)`` over the cells ``latent`` (``exact`` and ``q``: ``(K,)`` marginals),
    ``q`` clamped to ``[EPS, 1 - EPS]``."""
    q = torch.as_tensor(q, dtype=torch.float64).detach()
    return float(kl_divergence(exact[latent], q[latent].clamp(EPS, 1 - EPS)))


@dataclass
class Record:
    """One method on one problem: the final summed KL and seconds, and for anytime methods the curve
    ``[(budget, seconds, kl)]`` (budget in sweeps or steps)."""

    method: str
    kind: str  # "exact", "one pass", "anytime"
    kl: float
    seconds: float
    curve: list = field(default_factory=list)
    unit: str = ""
    note: str = ""
    datasets: int = 1

    def time_to(self, target: float = TARGET) -> float | None:
        """Seconds until the curve (or the one-pass estimate) first comes within ``target``."""
        pts = self.curve or [(0, self.seconds, self.kl)]
        return next((s for _, s, k in pts if k <= target), None)
