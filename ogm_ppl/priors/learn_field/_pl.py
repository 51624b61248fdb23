r"""Maximum pseudo-likelihood fit of a pattern field (Besag), and the back-off potentials that centre its
penalty.

``max_theta  1/N sum_k log p(m_k | m_-k; theta) - lambda_/2 |theta - theta0|^2``: the conditional of a cell
depends on the data only through its neighbourhood, so the objective is a weighted sum over the distinct
neighbourhood keys of :class:`~ogm_ppl.priors.learn_field._stats.FieldStats` (exact, and cheap enough for LBFGS).
``theta`` is tied over the 8 symmetries (one parameter per orbit); the L2 penalty also fixes the gauge.
``theta0`` is 0 or the :func:`backoff_potentials` of a smaller field (unseen patterns then score as the
smaller, smoother field scores them).
"""

from __future__ import annotations

import time

import numpy as np
import torch

from ogm_ppl.priors.learn_field._stats import FieldStats
from ogm_ppl.priors.pattern_field import symmetry_orbits


class _PL:
    """The pseudo-log-likelihood of :class:`FieldStats` as a torch function of the orbit parameters."""

    def __init__(self, stats: FieldStats, scales: int):
        w = stats.w
        S = 2 * w - 1
        h = w - 1
        orbit, self.n = symmetry_orbits(w)
        self.orbit = torch.from_numpy(np.array(orbit))
        if scales == 2 and stats.scales != 2:
            raise ValueError("two-scale pseudo-likelihood needs FieldStats of scales = 2")
        keys = stats.keys2 if scales == 2 else stats.keys1
        counts = stats.counts2 if scales == 2 else stats.counts1
        centre = h * S + h
        self.y = torch.from_numpy(((keys >> centre) & 1).astype(np.float64))
        self.cnt = torch.from_numpy(counts.astype(np.float64))
        self.N = float(counts.sum())
        wm = (1 << w) - 1

        def windows(nb):
            c0, c1 = [], []
            for r0 in range(w):  # window anchor relative to the neighbourhood's top-left
                for q0 in range(w):
                    code = np.zeros(len(nb), np.int64)
                    for a in range(w):
                        code |= ((nb >> ((r0 + a) * S + q0)) & wm) << (a * w)
                    bit = 1 << ((h - r0) * w + (h - q0))
                    code &= ~bit
                    c0.append(code)
                    c1.append(code | bit)
            return torch.from_numpy(np.stack(c0, 1)), torch.from_numpy(np.stack(c1, 1))

        self.c0, self.c1 = windows(keys & ((1 << (S * S)) - 1))
        self.two = scales == 2
        if self.two:
            self.free = torch.from_numpy(((keys >> (S * S)) & 1).astype(np.float64))
            self.p0, self.p1 = windows(keys >> (S * S + 1))

    def log_odds(self, p1: torch.Tensor, p2: torch.Tensor | None) -> torch.Tensor:
        t1 = p1[self.orbit]
        lo = (t1[self.c1] - t1[self.c0]).sum(1)
        if self.two and p2 is not None:
            t2 = p2[self.orbit]
            lo = lo + self.free * (t2[self.p1] - t2[self.p0]).sum(1)
        return lo

    def pll(self, p1, p2=None) -> torch.Tensor:
        """Mean log-probability per cell of each cell given its neighbourhood."""
        lo = self.log_odds(p1, p2)
        return (self.cnt * torch.nn.functional.logsigmoid((2 * self.y - 1) * lo)).sum() / max(self.N, 1.0)


def validation_pll(stats: FieldStats, theta, theta2=None) -> float:
    """Mean validation pseudo-log-likelihood per cell (nats) of the orbit parameters."""
    pl = _PL(stats, 2 if theta2 is not None else 1)
    with torch.no_grad():
        t2 = None if theta2 is None else torch.as_tensor(theta2, dtype=torch.float64)
        return float(pl.pll(torch.as_tensor(theta, dtype=torch.float64), t2))


def backoff_potentials(phi, w_small: int = 2, w: int = 3) -> np.ndarray:
    r"""The ``w x w`` orbit parameters of a ``w_small x w_small`` field ``phi`` (its orbit parameters) spread
    over the larger windows: ``theta0[code] = sum over the (w - w_small + 1)^2 sub-windows s of the code of
    phi[s] / (w - w_small + 1)^2``. Away from the grid's edges every small window lies in exactly that many
    large ones, so the field of ``theta0`` equals the small field there: a smooth centre to shrink the large
    field's parameters to (patterns the data never showed get the small field's score instead of 0)."""
    orb_s, _ = symmetry_orbits(w_small)
    orb, n = symmetry_orbits(w)
    t_s = np.asarray(phi, np.float64)[np.asarray(orb_s)]
    codes = np.arange(1 << (w * w), dtype=np.int64)
    k = w - w_small + 1
    tot = np.zeros(len(codes))
    mask = (1 << w_small) - 1
    for r0 in range(k):
        for c0 in range(k):
            sub = np.zeros(len(codes), np.int64)
            for a in range(w_small):
                sub |= ((codes >> ((r0 + a) * w + c0)) & mask) << (a * w_small)
            tot += t_s[sub]
    tot /= k * k
    return np.bincount(np.asarray(orb), tot, n) / np.bincount(np.asarray(orb), minlength=n)


def fit_pl(
    stats: FieldStats,
    scales: int = 1,
    lambda_: float = 1e-4,
    max_iter: int = 200,
    progress: bool = True,
    theta0=None,
):
    """Maximum pseudo-likelihood orbit parameters ``(theta, theta2 or None, pll)`` by LBFGS (module docstring).
    ``theta0``: the centre of the scale-1 penalty, ``lambda_/2 |theta - theta0|^2`` (default 0; e.g.
    :func:`backoff_potentials` of a smaller field)."""
    pl = _PL(stats, scales)
    c1 = torch.zeros(pl.n, dtype=torch.float64) if theta0 is None else torch.as_tensor(theta0, dtype=torch.float64)
    p1 = c1.clone().requires_grad_(True)
    params = [p1]
    p2 = None
    if scales == 2:
        p2 = torch.zeros(pl.n, dtype=torch.float64, requires_grad=True)
        params.append(p2)
    opt = torch.optim.LBFGS(params, lr=1.0, max_iter=max_iter, line_search_fn="strong_wolfe", tolerance_grad=1e-9)
    centres = [c1] + ([torch.zeros(pl.n, dtype=torch.float64)] if scales == 2 else [])

    def closure():
        opt.zero_grad()
        pen = 0.5 * lambda_ * sum(((p - c) ** 2).sum() for p, c in zip(params, centres))
        loss = -pl.pll(p1, p2) + pen
        loss.backward()
        return loss

    t0 = time.perf_counter()
    opt.step(closure)
    with torch.no_grad():
        val = float(pl.pll(p1, p2))
        loss = -val + 0.5 * lambda_ * sum(float(((p - c) ** 2).sum()) for p, c in zip(params, centres))
    if progress:
        print(
            f"  PL: {len(pl.cnt):,} distinct neighbourhoods, objective {loss:.5f}, "
            f"PLL/cell {val:.5f} ({time.perf_counter() - t0:.1f} s)",
            flush=True,
        )
    th2 = None if p2 is None else p2.detach().numpy().copy()
    return p1.detach().numpy().copy(), th2, val
