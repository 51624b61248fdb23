r"""MCMC maximum likelihood of a pattern field from a pseudo-likelihood start: persistent contrastive
divergence (:func:`fit_pcd`, Tieleman 2008: Adam steps on ``f_data - f_model - lambda_ theta``, stopped by
the held-out frequency gap) and stochastic approximation (:func:`fit_mle`, Younes 1988: Robbins-Monro steps,
Fisher-preconditioned, Polyak-averaged, checked by fresh chains from both phases).
"""

from __future__ import annotations

import time

import numpy as np
import torch

from ogm_ppl.priors.compiled import prior_gibbs_sweeps
from ogm_ppl.priors.compiled.field import pattern_field
from ogm_ppl.priors.learn_field._check import FieldFit, _start_maps, sampler_check
from ogm_ppl.priors.learn_field._pl import _PL
from ogm_ppl.priors.learn_field._stats import FieldStats, _chain_freq
from ogm_ppl.priors.pattern_field import symmetry_orbits


def fit_pcd(
    train: FieldStats,
    val: FieldStats,
    theta,
    theta2=None,
    *,
    iterations: int = 200,
    chains: int = 16,
    size: int = 64,
    sweeps: int = 1,
    burn_in: int = 50,
    lr: float = 0.02,
    lambda_: float = 1e-4,
    eval_every: int = 20,
    seed: int = 0,
    init: np.ndarray | None = None,
    progress: bool = True,
) -> FieldFit:
    """PCD from the orbit parameters ``theta`` (``theta2``), stopping point by validation PLL (module
    docstring). Returns a :class:`FieldFit` whose ``occupancy`` is the chains' cell marginal at the
    chosen iterate (the centre ``(size - 16)^2`` cells). ``init``: the chains' start (``chains x size^2``
    uint8, e.g. :func:`data_crops`; default uniform noise)."""
    w = train.w
    orbit, n = symmetry_orbits(w)
    orbit = np.asarray(orbit)
    two = theta2 is not None
    p1 = torch.tensor(theta, dtype=torch.float64)
    p2 = torch.tensor(theta2, dtype=torch.float64) if two else torch.zeros(n, dtype=torch.float64)
    fd1 = torch.from_numpy(train.orbit_freq(1))
    fd2 = torch.from_numpy(train.orbit_freq(2))
    fv1, fv2 = val.orbit_freq(1), val.orbit_freq(2)
    vpl = _PL(val, 2 if two else 1)
    rng = np.random.default_rng(seed)
    if init is None:
        maps = np.ascontiguousarray(rng.random((chains, size * size)) < 0.5, dtype=np.uint8)
    else:
        maps = np.array(init, dtype=np.uint8).reshape(chains, size * size)

    def bundle():
        t1 = p1.numpy()[orbit]
        return pattern_field(size, size, w, t1, p2.numpy()[orbit] if two else None)

    def occ():
        return float(maps.reshape(chains, size, size)[:, 8:-8, 8:-8].mean())

    def score(f1, f2):
        gap = float(np.abs(fv1 - f1).sum()) + (float(np.abs(fv2 - f2).sum()) if two else 0.0)
        with torch.no_grad():
            return gap, float(vpl.pll(p1, p2 if two else None))

    prior_gibbs_sweeps(bundle(), maps, burn_in, int(rng.integers(2**31 - 1)))
    t0 = time.perf_counter()
    best_gap, pll0 = score(*_chain_freq(maps, size, w, orbit, n, two))
    curve = [(0, best_gap, pll0, 0.0)]
    best = (0, p1.clone(), p2.clone(), occ())
    if progress:
        print(f"  PCD it 0 (PL): held-out gap {best_gap:.4f}, validation PLL/cell {pll0:.5f}", flush=True)
    m1 = torch.zeros(n, dtype=torch.float64)
    v1 = torch.zeros(n, dtype=torch.float64)
    m2 = torch.zeros(n, dtype=torch.float64)
    v2 = torch.zeros(n, dtype=torch.float64)
    b1, b2, eps = 0.9, 0.999, 1e-8
    for it in range(1, iterations + 1):
        prior_gibbs_sweeps(bundle(), maps, sweeps, int(rng.integers(2**31 - 1)))
        f1, f2 = _chain_freq(maps, size, w, orbit, n, two)
        g1 = fd1 - torch.from_numpy(f1) - lambda_ * p1
        m1 = b1 * m1 + (1 - b1) * g1
        v1 = b2 * v1 + (1 - b2) * g1**2
        p1 = p1 + lr * (m1 / (1 - b1**it)) / ((v1 / (1 - b2**it)).sqrt() + eps)
        if two:
            g2 = fd2 - torch.from_numpy(f2) - lambda_ * p2
            m2 = b1 * m2 + (1 - b1) * g2
            v2 = b2 * v2 + (1 - b2) * g2**2
            p2 = p2 + lr * (m2 / (1 - b1**it)) / ((v2 / (1 - b2**it)).sqrt() + eps)
        if it % eval_every == 0 or it == iterations:
            # the chains have moved once under the new parameters: their frequencies score them
            prior_gibbs_sweeps(bundle(), maps, sweeps, int(rng.integers(2**31 - 1)))
            gap, val_pll = score(*_chain_freq(maps, size, w, orbit, n, two))
            secs = time.perf_counter() - t0
            curve.append((it, gap, val_pll, round(secs, 2)))
            if progress:
                print(
                    f"  PCD it {it}: held-out gap {gap:.4f}, validation PLL/cell {val_pll:.5f} ({secs:.1f} s)",
                    flush=True,
                )
            if gap < best_gap:
                best_gap = gap
                best = (it, p1.clone(), p2.clone(), occ())
    it, q1, q2, oc = best
    return FieldFit(w, q1.numpy(), q2.numpy() if two else None, it, best_gap, curve, oc)


def fit_mle(
    train: FieldStats,
    val: FieldStats,
    theta,
    theta2=None,
    *,
    iterations: int = 600,
    chains: int = 32,
    size: int = 64,
    sweeps: int = 2,
    burn_in: int = 100,
    lr: float = 0.3,
    decay: float = 100.0,
    floor: float = 1e-4,
    lambda_: float = 1e-3,
    eval_every: int = 100,
    check_sweeps: int = 200,
    check_chains: int = 4,
    check_starts: tuple[str, ...] = ("free", "occupied"),
    check_data: np.ndarray | None = None,
    seed: int = 0,
    init: np.ndarray | None = None,
    progress: bool = True,
) -> FieldFit:
    r"""Penalised maximum likelihood by stochastic approximation (MCMC-MLE, Younes 1988 / Robbins-Monro).

    The penalised log-likelihood ``l(theta) = sum_k n_k theta_k - N log Z(theta) - lambda_/2 |theta|^2``
    (``n_k``: count of windows of orbit ``k``; per window ``grad = f_data - f_model - lambda_ theta``) is
    climbed by

    .. math:: \theta \leftarrow \theta + \frac{a}{1 + t / t_0}\,
              \frac{f_\mathrm{data} - \hat f_t - \lambda \theta}{(f_\mathrm{data} + \hat f_t) / 2 + \epsilon},

    ``a = lr``, ``t_0 = decay``, ``epsilon = floor``: a Robbins-Monro step size (sum infinite, sum of squares
    finite) preconditioned by the diagonal of the multinomial Fisher information ``diag(f)`` (a step in the
    log-frequency scale, so rare and common orbits move alike; each coordinate's data step clipped to
    ``[-1, 1]``, the penalty's step taken implicitly, ``theta <- theta / (1 + h lambda_)`` with ``h`` the
    coordinate's step size, which is stable however large ``h lambda_`` is). ``\hat f_t`` are the orbit
    frequencies of ``chains`` persistent ``size x size`` chains averaged over ``sweeps`` compiled sweeps per
    iteration (after ``burn_in`` sweeps under the start), half of them started all-free and half
    all-occupied (or from ``init``), so the negative phase holds both phases. The returned parameters are
    Polyak-Ruppert averages of the iterates from ``iterations / 4`` on.

    **Stopping point.** Every ``eval_every`` iterations the current average is checked with *fresh*
    chains (:func:`sampler_check`, ``check_chains`` chains, ``check_sweeps`` sweeps, from all-free and from
    all-occupied starts) against the validation maps; its score is the *larger* of the two starts'
    held-out gaps, so a field whose samples depend on the start (an ordered phase) scores badly. The
    smallest score is kept. ``occupancy`` is the mean of the two starts' cell marginals at that iterate.
    Deterministic for a seed. (``theta2``: the scale-2 parameters, fitted jointly; ``None``: one scale.)
    """
    w = train.w
    orbit, n = symmetry_orbits(w)
    orbit = np.asarray(orbit)
    two = theta2 is not None
    p = [np.array(theta, np.float64)] + ([np.array(theta2, np.float64)] if two else [])
    fd = [train.orbit_freq(1)] + ([train.orbit_freq(2)] if two else [])
    rng = np.random.default_rng(seed)
    if init is None:
        half = chains // 2
        maps = np.concatenate([_start_maps("free", half, size, rng), _start_maps("occupied", chains - half, size, rng)])
    else:
        maps = np.array(init, dtype=np.uint8).reshape(chains, size * size)

    def bundle(q):
        return pattern_field(size, size, w, q[0][orbit], q[1][orbit] if two else None)

    def check(q):
        rows = sampler_check(
            q[0],
            q[1] if two else None,
            w,
            val,
            sizes=(size,),
            starts=check_starts,
            chains=check_chains,
            sweeps=check_sweeps,
            seed=int(rng.integers(2**31 - 1)),
            data=check_data,
        )
        return max(r["gap"] for r in rows), float(np.mean([r["occupancy"] for r in rows]))

    t0 = time.perf_counter()
    gap0, occ0 = check(p)
    curve = [(0, gap0, occ0, 0.0)]
    best = (0, [q.copy() for q in p], gap0, occ0)
    if progress:
        print(f"  MLE it 0: held-out gap (worse start) {gap0:.4f}, occupancy {occ0:.3f}", flush=True)
    prior_gibbs_sweeps(bundle(p), maps, burn_in, int(rng.integers(2**31 - 1)))
    avg = [q.copy() for q in p]
    n_avg = 0
    start_avg = max(1, iterations // 4)
    for it in range(1, iterations + 1):
        b = bundle(p)
        fm = [np.zeros(n) for _ in p]
        for _ in range(sweeps):
            prior_gibbs_sweeps(b, maps, 1, int(rng.integers(2**31 - 1)))
            a1, a2 = _chain_freq(maps, size, w, orbit, n, two)
            fm[0] += a1 / sweeps
            if two:
                fm[1] += a2 / sweeps
        step = lr / (1.0 + it / decay)
        for q, d, m in zip(p, fd, fm):
            h = step / (0.5 * (d + m) + floor)
            q += np.clip(h * (d - m), -1.0, 1.0)
            q /= 1.0 + h * lambda_  # the penalty's step taken implicitly (proximal): stable for any lambda_
        if it >= start_avg:
            n_avg += 1
            for a, q in zip(avg, p):
                a += (q - a) / n_avg
        else:
            for a, q in zip(avg, p):
                a[:] = q
        if it % eval_every == 0 or it == iterations:
            gap, oc = check(avg)
            secs = time.perf_counter() - t0
            curve.append((it, gap, oc, round(secs, 2)))
            if progress:
                print(f"  MLE it {it}: held-out gap (worse start) {gap:.4f}, occupancy {oc:.3f} ({secs:.1f} s)")
            if gap < best[2]:
                best = (it, [a.copy() for a in avg], gap, oc)
    it, qs, gap, oc = best
    return FieldFit(w, qs[0], qs[1] if two else None, it, gap, curve, oc)
