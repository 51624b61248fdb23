r"""Learning a pattern field (:class:`~ogm_ppl.priors.PatternFieldPrior`) from training maps, in torch.

The field ``log p~(m) = sum_windows theta[code]`` (``+ sum_pooled windows theta2[code]``) is fitted in
stages (Felzenszwalb & Oberlin 2014 fit by contrastive divergence; here pseudo-likelihood starts it; the
shipped fits use stages 1, 3 and 4 below):

1. **Maximum pseudo-likelihood** (Besag):
   ``max_theta  1/N sum_k log p(m_k | m_-k; theta) - lambda_/2 |theta|^2``, the sum over every cell whose
   ``(2w - 1)^2`` neighbourhood (at two scales also its pooled parent's ``(2w - 1)^2`` pooled neighbourhood)
   lies inside the grid and in known cells. The conditional depends on the data only through that
   neighbourhood, so the objective is a weighted sum over the *distinct* neighbourhood codes
   (:class:`FieldStats`): exact, and cheap enough for LBFGS. ``theta`` is tied over the 8 symmetries (one
   parameter per orbit, :func:`~ogm_ppl.priors.pattern_field.symmetry_orbits`); the L2 penalty also fixes
   the gauge (adding a constant to every ``theta`` leaves the conditionals unchanged).
2. **Persistent contrastive divergence** (MCMC maximum likelihood, Tieleman 2008): per iteration,
   ``grad = f_data - f_model - lambda_ theta``, where ``f`` are per-window orbit frequencies (scale 2: per
   pooled window) of the training data (windows wholly in known cells) and of persistent prior-only Gibbs
   chains (``chains x size x size`` maps, ``sweeps`` compiled sweeps per iteration,
   :func:`~ogm_ppl.priors.compiled.prior_gibbs_sweeps`); Adam steps.

The chains start from crops of the training maps (:func:`data_crops`; from noise a strongly coupled field
freezes in noise-like states), and run ``burn_in`` sweeps under the PL solution first. Stopping point: every
``eval_every`` iterations the *held-out frequency gap* ``|f_val - f_model|_1`` (summed over the scales) of
the persistent chains; the iterate with the smallest gap is returned. :func:`fit_mle` is the same
stochastic approximation with a Robbins-Monro step, a Fisher-preconditioned gradient and Polyak averaging,
checked by fresh chains from both phases.

**Why the shipped fields are tempered PL fields.** Rasterised plans are nearly deterministic at the scale of
a window (validation PLL about -0.001 nats per cell): the PL field is *ordered*. The compiled sampler keeps
the all-free map free and the all-occupied one occupied (:func:`sampler_check`), and noise freezes into
stripes and specks, since with the penalty centred at 0 every pattern the plans never showed scores about
the same, so nothing pulls a map back to plan-like patterns. PCD cannot repair this: its chains never
cross between the phases, so the negative phase is a start-dependent mixture and the steps oscillate.
Two changes fix the prior:

3. **Backoff centre.** The penalty is ``lambda_/2 |theta - theta0|^2`` with ``theta0`` the
   :func:`backoff_potentials` of a ``2 x 2`` field fitted by PL first: unseen ``3 x 3`` patterns score as the
   smaller, smoother field scores them (a restoring force; noise now coarsens to plan-like textures).
4. **Tempering** (:func:`fit_tempered`): the tempered family ``beta theta`` has a sharp transition between
   a disordered phase and the two ordered ones; the chosen ``beta`` is the largest whose chains from the
   all-free and the all-occupied map agree, closest to the validation maps' window frequencies, with a
   unary bias (:func:`unary_orbits`) that gives the prior samples the training maps' occupied share.
   :func:`fit_pattern_field` is this recipe.
"""

from __future__ import annotations

import time
from collections.abc import Iterable
from dataclasses import dataclass, field

import numba as nb
import numpy as np
import torch

from ogm_ppl.priors.compiled import prior_gibbs_sweeps
from ogm_ppl.priors.compiled.field import field_window_codes, pattern_field
from ogm_ppl.priors.learn import _as_pair as _as_pair_checked
from ogm_ppl.priors.pattern_field import PatternFieldPrior, symmetry_orbits

__all__ = [
    "FieldFit",
    "FieldStats",
    "data_crops",
    "backoff_potentials",
    "field_stats",
    "sampler_check",
    "fit_pattern_field",
    "fit_pl",
    "fit_mle",
    "fit_pcd",
    "fit_tempered",
    "unary_orbits",
    "validation_pll",
]


# ------------------------------------------------------------------ sufficient statistics
@nb.njit(cache=True)
def _nbhd_keys(g, bad, w, two):
    """Per eligible cell of a 2D grid the key of its conditional: bits ``0..S^2-1`` its ``S x S``
    neighbourhood (``S = 2w - 1``, centre included); a cell is eligible when that neighbourhood lies in
    the grid and in known cells (``bad``: 1 for unknown cells). With ``two`` also the two-scale keys of
    the cells whose parent's pooled ``S x S`` neighbourhood lies in the pooled grid and in known pooled
    cells: bit ``S^2`` = the rest of the cell's ``2 x 2`` block is free, bits ``S^2 + 1 ..`` the pooled
    neighbourhood (parent cleared). Returns ``(keys1, keys2)``."""
    R, C = g.shape
    S = 2 * w - 1
    h = w - 1
    P = (R + 1) // 2
    Q = (C + 1) // 2
    pg = np.zeros((P, Q), np.uint8)
    pbad = np.zeros((P, Q), np.uint8)
    for r in range(R):
        for c in range(C):
            pg[r >> 1, c >> 1] |= g[r, c]
            pbad[r >> 1, c >> 1] |= bad[r, c]
    # prefix sums of unknown cells, to test a neighbourhood in O(1)
    cb = np.zeros((R + 1, C + 1), np.int64)
    for r in range(R):
        for c in range(C):
            cb[r + 1, c + 1] = cb[r, c + 1] + cb[r + 1, c] - cb[r, c] + bad[r, c]
    pb = np.zeros((P + 1, Q + 1), np.int64)
    for r in range(P):
        for c in range(Q):
            pb[r + 1, c + 1] = pb[r, c + 1] + pb[r + 1, c] - pb[r, c] + pbad[r, c]
    out1 = np.empty(R * C, np.int64)
    out2 = np.empty(R * C if two else 0, np.int64)
    n1 = 0
    n2 = 0
    for r in range(h, R - h):
        for c in range(h, C - h):
            if cb[r + h + 1, c + h + 1] - cb[r - h, c + h + 1] - cb[r + h + 1, c - h] + cb[r - h, c - h] > 0:
                continue
            key = np.int64(0)
            for a in range(S):
                for b in range(S):
                    if g[r - h + a, c - h + b]:
                        key |= np.int64(1) << (a * S + b)
            out1[n1] = key
            n1 += 1
            if two:
                pr = r >> 1
                pc = c >> 1
                if pr < h or pc < h or pr + h >= P or pc + h >= Q:
                    continue
                if (
                    pb[pr + h + 1, pc + h + 1] - pb[pr - h, pc + h + 1] - pb[pr + h + 1, pc - h] + pb[pr - h, pc - h]
                    > 0
                ):
                    continue
                free = 1
                for i in range(2 * pr, min(2 * pr + 2, R)):
                    for j in range(2 * pc, min(2 * pc + 2, C)):
                        if (i != r or j != c) and g[i, j]:
                            free = 0
                key |= np.int64(free) << (S * S)
                for a in range(S):
                    for b in range(S):
                        if (a != h or b != h) and pg[pr - h + a, pc - h + b]:
                            key |= np.int64(1) << (S * S + 1 + a * S + b)
                out2[n2] = key
                n2 += 1
    return out1[:n1], out2[:n2]


def _pooled_np(g: np.ndarray) -> np.ndarray:
    R, C = g.shape
    x = np.zeros((R + R % 2, C + C % 2), np.uint8)
    x[:R, :C] = g
    return x.reshape(x.shape[0] // 2, 2, x.shape[1] // 2, 2).max((1, 3))


@dataclass
class FieldStats:
    """Sufficient statistics of a set of maps for fitting a ``w x w`` field at one or two scales:
    ``keys1``/``counts1`` the distinct one-scale conditional keys (:func:`_nbhd_keys`) and their counts,
    ``keys2``/``counts2`` the two-scale ones (empty when ``scales == 1``), ``win1`` (``2^(w w)``) the counts
    of the window codes wholly in known cells, ``win2`` those of the pooled grid."""

    w: int
    scales: int
    keys1: np.ndarray
    counts1: np.ndarray
    keys2: np.ndarray
    counts2: np.ndarray
    win1: np.ndarray
    win2: np.ndarray
    n_maps: int = 0
    n_cells: int = 0

    def orbit_freq(self, scale: int = 1) -> np.ndarray:
        """Per-window frequency of each orbit (``n_orbits``)."""
        orbit, n = symmetry_orbits(self.w)
        c = self.win1 if scale == 1 else self.win2
        return np.bincount(orbit, c.astype(np.float64), n) / max(c.sum(), 1)


def _as_pair(item, index: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """``(occupancy, known)`` bool arrays of a map as :func:`~ogm_ppl.priors.learn.count_tables` takes it (checked
    the same way), every cell known where it says nothing of them."""
    occ, known = _as_pair_checked(item, index)
    return occ, np.ones_like(occ) if known is None else known


def field_stats(maps: Iterable, w: int = 3, scales: int = 1) -> FieldStats:
    """:class:`FieldStats` of a stream of maps (``H x W`` bool arrays, ``(occupancy, known)`` pairs, or
    :class:`~ogm_ppl.datasets.floorplans.FloorPlan`\\ s)."""
    if scales not in (1, 2):
        raise ValueError(f"scales must be 1 or 2, got {scales}")
    if scales == 2 and 2 * (2 * w - 1) ** 2 + 1 > 63:
        raise ValueError(f"a two-scale key of w = {w} does not fit 63 bits")
    n_codes = 1 << (w * w)
    win1 = np.zeros(n_codes, np.int64)
    win2 = np.zeros(n_codes, np.int64)
    acc: list[list[np.ndarray]] = [[], [], [], []]
    n_maps = n_cells = 0
    for index, item in enumerate(maps):
        occ, known = _as_pair(item, index)
        g = np.ascontiguousarray(occ & known, np.uint8)
        bad = np.ascontiguousarray(~known, np.uint8)
        for i, k in enumerate(_nbhd_keys(g, bad, w, scales == 2)):
            u, c = np.unique(k, return_counts=True)
            acc[2 * i].append(u)
            acc[2 * i + 1].append(c)
        c1 = field_window_codes(g, w)
        b1 = field_window_codes(bad, w)
        win1 += np.bincount(c1[b1 == 0], minlength=n_codes)
        pg, pbad = _pooled_np(g), _pooled_np(bad)
        c2 = field_window_codes(pg, w)
        b2 = field_window_codes(pbad, w)
        win2 += np.bincount(c2[b2 == 0], minlength=n_codes)
        n_maps += 1
        n_cells += occ.size
    return FieldStats(w, scales, *_merge(acc[0], acc[1]), *_merge(acc[2], acc[3]), win1, win2, n_maps, n_cells)


def _merge(keys: list[np.ndarray], counts: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    if not keys:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    u, inv = np.unique(np.concatenate(keys), return_inverse=True)
    return u.astype(np.int64), np.bincount(inv, np.concatenate(counts)).astype(np.int64)


# ------------------------------------------------------------------ pseudo-likelihood
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


# ------------------------------------------------------------------ persistent contrastive divergence
def _chain_freq(maps: np.ndarray, size: int, w: int, orbit: np.ndarray, n: int, two: bool):
    n_codes = 1 << (w * w)
    c1 = np.zeros(n_codes, np.float64)
    c2 = np.zeros(n_codes, np.float64)
    for m in maps:
        g = m.reshape(size, size)
        c1 += np.bincount(field_window_codes(g, w).ravel(), minlength=n_codes)
        if two:
            c2 += np.bincount(field_window_codes(_pooled_np(g), w).ravel(), minlength=n_codes)
    f1 = np.bincount(orbit, c1, n) / c1.sum()
    f2 = np.bincount(orbit, c2, n) / max(c2.sum(), 1.0)
    return f1, f2


def data_crops(maps: Iterable, chains: int, size: int, seed: int = 0, tries: int = 200) -> np.ndarray:
    """``chains x size^2`` uint8 crops of the maps (``(occupancy, known)`` pairs or bool arrays), each at a
    seeded random map and offset, preferring crops wholly in known cells (unknown cells read as occupied)."""
    pairs = [_as_pair(m, i) for i, m in enumerate(maps)]
    pairs = [(o, k) for o, k in pairs if o.shape[0] >= size and o.shape[1] >= size]
    if not pairs:
        raise ValueError(f"no map is at least {size} x {size} cells")
    rng = np.random.default_rng(seed)
    out = np.empty((chains, size * size), np.uint8)
    for b in range(chains):
        for _ in range(tries):
            o, k = pairs[int(rng.integers(len(pairs)))]
            r = int(rng.integers(o.shape[0] - size + 1))
            c = int(rng.integers(o.shape[1] - size + 1))
            if k[r : r + size, c : c + size].all():
                break
        out[b] = (o | ~k)[r : r + size, c : c + size].ravel()
    return out


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


# ------------------------------------------------------------------ MCMC maximum likelihood, checked from both phases
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
