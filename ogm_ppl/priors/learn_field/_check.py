"""A fitted pattern field (:class:`FieldFit`) and what the compiled prior sampler draws from a field's
parameters (:func:`sampler_check`): prior-only Gibbs chains from given starts, their cell marginal and the gap
of their window frequencies to reference maps. A field that mixes gives the same numbers from every start; an
ordered (bistable) one keeps each start's phase.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field

import numpy as np

from ogm_ppl.priors.compiled import prior_gibbs_sweeps
from ogm_ppl.priors.compiled.field import pattern_field
from ogm_ppl.priors.learn_field._stats import FieldStats, _chain_freq
from ogm_ppl.priors.pattern_field import PatternFieldPrior, symmetry_orbits


@dataclass
class FieldFit:
    """A fitted field: orbit parameters, the curve of the search (:func:`fit_pcd`: ``(iteration, held-out
    frequency gap, validation PLL per cell, seconds)``; :func:`fit_mle`: ``(iteration, gap, occupancy,
    seconds)``; :func:`fit_tempered`: ``(beta, gap, occupancy from all-free, occupancy from all-occupied)``),
    the chosen iteration (0: the start) and, for :func:`fit_tempered`, the chosen power ``beta``."""

    w: int
    theta: np.ndarray
    theta2: np.ndarray | None
    best_iteration: int
    best_gap: float
    curve: list = field(default_factory=list)
    occupancy: float = float("nan")
    beta: float = 1.0

    def prior(self, shape) -> PatternFieldPrior:
        """The fitted field over a grid of ``shape``: a :class:`~ogm_ppl.priors.PatternFieldPrior` (one or two
        scales as fitted), which :func:`~ogm_ppl.priors.pattern_field.save_field` writes."""
        return PatternFieldPrior(shape, self.theta, self.w, theta2=self.theta2, occupancy=self.occupancy)


def _start_maps(start: str, chains: int, size: int, rng: np.random.Generator) -> np.ndarray:
    if start == "free":
        return np.zeros((chains, size * size), np.uint8)
    if start == "occupied":
        return np.ones((chains, size * size), np.uint8)
    if start == "noise":
        return np.ascontiguousarray(rng.random((chains, size * size)) < 0.5, dtype=np.uint8)
    raise ValueError(f"start must be 'free', 'occupied' or 'noise', got {start!r}")


def sampler_check(
    theta,
    theta2=None,
    w: int = 3,
    ref: FieldStats | None = None,
    *,
    sizes: Iterable[int] = (64,),
    starts: Iterable[str] = ("free", "occupied"),
    chains: int = 4,
    sweeps: int = 300,
    keep: int = 100,
    seed: int = 0,
    data: np.ndarray | None = None,
) -> list[dict]:
    r"""What the compiled prior sampler draws from the field of orbit parameters ``theta`` (``theta2``).

    For each grid side ``size`` and start (``"free"``: all cells 0, ``"occupied"``: all 1, ``"noise"``:
    uniform noise, ``"data"``: the maps ``data``, ``n x size^2`` uint8, e.g. :func:`data_crops`), ``chains``
    (``n`` for ``"data"``) prior-only single-cell Gibbs chains on ``size x size`` grids run ``sweeps`` sweeps; over the
    last ``keep`` (read every 10 sweeps) it records the cell marginal ``occupancy`` of the centre cells (8
    cells from the edge left out) and the per-window orbit frequencies ``f_1`` (``f_2`` on the pooled
    grid). With ``ref`` it adds ``gap = |f_ref,1 - f_1|_1 (+ |f_ref,2 - f_2|_1 at two scales)``, the
    distance of the field's window statistics to those of the reference maps. A field that mixes gives
    the same numbers from every start; an ordered (bistable) one keeps each start's phase.
    Returns one dict ``{size, start, occupancy, gap}`` per (size, start).
    """
    orbit, n = symmetry_orbits(w)
    orbit = np.asarray(orbit)
    two = theta2 is not None
    t1 = np.asarray(theta, np.float64)[orbit]
    t2 = None if not two else np.asarray(theta2, np.float64)[orbit]
    rng = np.random.default_rng(seed)
    keep = max(10, min(int(keep), int(sweeps)))
    out = []
    for size in sizes:
        b = pattern_field(size, size, w, t1, t2)
        for start in starts:
            if start == "data":
                if data is None or np.shape(data)[1:] != (size * size,):
                    raise ValueError(f"start 'data' needs data maps of {size * size} cells")
                maps = np.array(data, np.uint8)
            else:
                maps = _start_maps(start, chains, size, rng)
            prior_gibbs_sweeps(b, maps, sweeps - keep, int(rng.integers(2**31 - 1)))
            f1 = np.zeros(n)
            f2 = np.zeros(n)
            occ = 0.0
            reads = keep // 10
            for _ in range(reads):
                prior_gibbs_sweeps(b, maps, 10, int(rng.integers(2**31 - 1)))
                a1, a2 = _chain_freq(maps, size, w, orbit, n, two)
                f1 += a1 / reads
                f2 += a2 / reads
                e = min(8, size // 4)
                occ += float(maps.reshape(len(maps), size, size)[:, e : size - e, e : size - e].mean()) / reads
            row = {"size": int(size), "start": start, "occupancy": occ}
            if ref is not None:
                gap = float(np.abs(ref.orbit_freq(1) - f1).sum())
                if two:
                    gap += float(np.abs(ref.orbit_freq(2) - f2).sum())
                row["gap"] = gap
            out.append(row)
    return out
