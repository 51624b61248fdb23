"""Tempering of a fitted pattern field, ``p_beta(m) propto p~(m)^beta`` with a unary bias
(:func:`fit_tempered`): the strongest coupling whose prior samples agree from the all-free and the
all-occupied start, closest to the validation maps; and the shipped recipe (:func:`fit_pattern_field`):
a back-off field by pseudo-likelihood, the field by pseudo-likelihood centred on it, then tempering.
"""

from __future__ import annotations

import time
from collections.abc import Iterable

import numpy as np

from ogm_ppl.priors.learn_field._check import FieldFit, sampler_check
from ogm_ppl.priors.learn_field._pl import backoff_potentials, fit_pl
from ogm_ppl.priors.learn_field._stats import FieldStats, field_stats
from ogm_ppl.priors.pattern_field import symmetry_orbits


def unary_orbits(w: int = 3) -> np.ndarray:
    """Per orbit the share of occupied cells of its windows (``popcount / w^2``): adding ``b`` times this to
    the orbit parameters adds ``b`` to the log-odds of every cell whose ``w^2`` windows lie in the grid
    (a unary term, the field's bias)."""
    orbit, n = symmetry_orbits(w)
    codes = np.arange(1 << (w * w), dtype=np.int64)
    pop = ((codes[:, None] >> np.arange(w * w)) & 1).sum(1) / (w * w)
    return np.bincount(np.asarray(orbit), pop, n) / np.bincount(np.asarray(orbit), minlength=n)


def fit_tempered(
    val: FieldStats,
    theta,
    theta2=None,
    *,
    betas: Iterable[float] = tuple(np.round(np.arange(0.3, 1.0001, 0.05), 3)),
    occupancy: float | None = None,
    bias_steps: int = 5,
    bias_range: float = 1.5,
    size: int = 64,
    chains: int = 4,
    sweeps: int = 300,
    agree: float = 0.1,
    seed: int = 0,
    progress: bool = True,
) -> FieldFit:
    r"""The power ``beta`` of a fitted field (``p_beta(m) propto p~(m)^beta``: every potential times ``beta``),
    with an optional unary bias: the strongest coupling whose prior samples do not depend on the start,
    closest to the validation maps.

    A pseudo-likelihood fit of maps as regular as rasterised floor plans (conditional entropy near 0) is
    an ordered field: the compiled sampler keeps the all-free map almost free and the all-occupied one
    occupied (two phases), and tempering it shows a first-order transition between them and a
    disordered phase. For each ``beta`` :func:`sampler_check` runs ``chains`` fresh ``size x size``
    chains from the all-free and from the all-occupied map (``sweeps`` sweeps). The two starts *agree*
    when their cell marginals differ by at most ``agree``; among the agreeing powers the one with the
    smallest mean held-out gap ``|f_val - f_model|_1`` of the two starts wins (the gap falls as ``beta``
    grows towards the transition, so this is the largest agreeing ``beta``: the longest correlations that
    still mix). With a target ``occupancy`` a power also needs its mean marginal within ``agree`` of it. When
    no power qualifies, the smallest larger-of-the-two gap wins.

    **Bias.** With a target ``occupancy`` (e.g. the training maps' cell share), the scale-1 parameters get
    ``+ b`` :func:`unary_orbits` (a log-odds shift ``b`` per cell), ``b`` set at each ``beta`` by
    ``bias_steps`` bisection steps on ``[b' - bias_range, b' + bias_range]`` (``b'`` the previous ``beta``'s
    bias, 0 at first) of the mean occupancy of the two starts against the target (the occupancy rises
    with ``b``; near the transition steeply, so fixed-point steps overshoot), then scored as above.

    ``curve`` holds ``(beta, mean gap, occupancy from all-free, occupancy from all-occupied, b)``,
    ``best_gap`` the winner's mean gap, ``occupancy`` the mean of the two marginals at the chosen ``beta``.
    The returned ``theta`` includes the bias. Deterministic for a seed.
    """
    two = theta2 is not None
    w = val.w
    th = np.asarray(theta, np.float64)
    th2 = None if not two else np.asarray(theta2, np.float64)
    u = unary_orbits(w)
    curve = []
    best = None
    b = 0.0
    t0 = time.perf_counter()

    def run(beta: float, b: float):
        rows = sampler_check(
            beta * th + b * u,
            None if th2 is None else beta * th2,
            w,
            val,
            sizes=(size,),
            starts=("free", "occupied"),
            chains=chains,
            sweeps=sweeps,
            seed=seed,
        )
        return [r["gap"] for r in rows], {r["start"]: r["occupancy"] for r in rows}

    for beta in betas:
        if occupancy is None or bias_steps < 1:
            gaps, occ = run(beta, b)
        else:
            lo, hi = b - bias_range, b + bias_range
            for _ in range(bias_steps):
                b = 0.5 * (lo + hi)
                gaps, occ = run(beta, b)
                if 0.5 * (occ["free"] + occ["occupied"]) > occupancy:
                    hi = b
                else:
                    lo = b
        mean_occ = 0.5 * (occ["free"] + occ["occupied"])
        ok = abs(occ["free"] - occ["occupied"]) <= agree and (occupancy is None or abs(mean_occ - occupancy) <= agree)
        key = (0 if ok else 1, float(np.mean(gaps)) if ok else max(gaps))
        curve.append((float(beta), float(np.mean(gaps)), occ["free"], occ["occupied"], b))
        if progress:
            print(
                f"  beta {beta:.3f}, bias {b:+.3f}: held-out gap {np.mean(gaps):.4f} (worse start {max(gaps):.4f}), "
                f"occupancy from free {occ['free']:.3f} / occupied {occ['occupied']:.3f} "
                f"({time.perf_counter() - t0:.1f} s)",
                flush=True,
            )
        if best is None or key < best[3]:
            best = (float(beta), float(np.mean(gaps)), 0.5 * (occ["free"] + occ["occupied"]), key, b)
    if best is None:
        raise ValueError("betas must not be empty")
    beta, score, occ_best, _, b = best
    return FieldFit(w, beta * th + b * u, None if th2 is None else beta * th2, 0, score, curve, occ_best, beta)


def fit_pattern_field(
    train_maps: Iterable,
    val_maps: Iterable,
    w: int = 3,
    scales: int = 1,
    *,
    lambda_: float = 1e-2,
    backoff_w: int | None = 2,
    backoff_lambda_: float = 1e-3,
    betas: Iterable[float] = tuple(np.round(np.arange(0.3, 1.0001, 0.05), 3)),
    size: int = 64,
    seed: int = 0,
    progress: bool = True,
) -> FieldFit:
    """The shipped recipe (module docstring): a ``backoff_w x backoff_w`` field by PL (penalty
    ``backoff_lambda_``), the ``w x w`` field by PL with the penalty ``lambda_/2 |theta - theta0|^2`` centred
    on its :func:`backoff_potentials` (``backoff_w = None``: centred at 0), then :func:`fit_tempered` on the
    validation maps (chains of ``size x size``), its bias matched to the training windows' centre-cell
    occupied share."""
    train_maps, val_maps = list(train_maps), list(val_maps)
    tr, va = field_stats(train_maps, w, scales), field_stats(val_maps, w, scales)
    for what, maps, st in (("training", train_maps, tr), ("validation", val_maps, va)):
        if not maps:
            raise ValueError(f"fit_pattern_field: no {what} maps (the validation maps choose the power beta)")
        if st.win1.sum() == 0:
            raise ValueError(f"fit_pattern_field: the {what} maps hold no {w} x {w} window of known cells")
    theta0 = None
    if backoff_w is not None:
        phi, _, _ = fit_pl(field_stats(train_maps, backoff_w, 1), 1, backoff_lambda_, progress=progress)
        theta0 = backoff_potentials(phi, backoff_w, w)
    th, th2, _ = fit_pl(tr, scales, lambda_, progress=progress, theta0=theta0)
    occ = float(tr.win1 @ ((np.arange(len(tr.win1)) >> (w * w // 2)) & 1) / max(tr.win1.sum(), 1))
    return fit_tempered(va, th, th2, betas=betas, occupancy=occ, size=size, seed=seed, progress=progress)
