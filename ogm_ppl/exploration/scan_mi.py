r"""The nested Monte-Carlo mutual information ``I(m; Z)`` of whole scans, compiled once per reading kind.

For candidate ``c`` with beams ``b = 1..B``, the samples ``s`` with the candidate's cell free (weights ``w_s``
renormalised over them), ``F_s`` the first hits of all beams in sample ``s`` and
``p_S(Z) = sum_s w_s p(Z | F_s)`` with ``p(Z | F_s) = prod_b p(z_b | f_{s,b})`` (beams independent given the
map), each draw ``n = 1..N`` picks ``s_n ~ w`` (by the uniform ``u_pick``), draws ``Z_n ~ p(. | F_{s_n})`` beam by
beam (the reading kind's ``draw`` from ``u_a``, ``u_b``, ``eps``) and scores

.. math::
    t_n = \log p(Z_n \mid F_{s_n}) - \log \sum_s w_s\, p(Z_n \mid F_s),

the inner sum computed exactly (log-sum-exp). The kernel returns the mean of the ``t_n`` and their sample
variance (Welford), in nats. A beam's ``log p(z_b | f)`` depends on ``f`` alone, so it is evaluated once per
distinct first hit of the beam among the samples (the groups of :func:`first_hit_groups`).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba as nb
import numpy as np

from ogm_ppl._numba_cache import njit_shipped
from ogm_ppl.exploration.first_hits import PackedSamples, ctz
from ogm_ppl.exploration.rays import RayTable
from ogm_ppl.sensors_compiled import coord, draw, log_reading, num_outcomes

__all__ = ["Draws", "first_hit_groups", "kept_samples", "sample_first_hits", "scan_mi_kernel"]


class Draws(NamedTuple):
    """The random numbers of the estimator (one numba argument): ``u_pick`` ``C x N`` uniforms (the sample
    of each draw), and ``C x N x B`` each: ``eps`` standard normals, ``u_a`` and ``u_b`` uniforms (each
    beam's reading, by the reading kind's ``draw``)."""

    u_pick: np.ndarray
    eps: np.ndarray
    u_a: np.ndarray
    u_b: np.ndarray


@nb.njit(cache=True)
def kept_samples(samples: PackedSamples, pose_cell):
    """The samples of positive weight with ``pose_cell`` free: ``(loc, kept, n)``, ``kept[:n]`` their indices
    in order and ``loc[s]`` the position of sample ``s`` among them (``-1``: left out)."""
    packed, w, valid_mask = samples.packed, samples.w, samples.valid_mask
    S = w.shape[0]
    one = np.uint64(1)
    loc = np.full(S, -1, np.int64)
    vs = np.empty(S, np.int64)
    nv = 0
    for k in range(packed.shape[1]):
        x = ~packed[pose_cell, k] & valid_mask[k]
        while x != 0:
            s = k * 64 + ctz(x)
            if w[s] > 0.0:
                loc[s] = nv
                vs[nv] = s
                nv += 1
            x &= x - one
    return loc, vs, nv


@nb.njit(cache=True)
def _log_weights(w, vs, nv):
    """The kept samples' log weights renormalised over them, and their cumulative weights."""
    lw = np.empty(nv)
    cw = np.empty(nv)
    tot = 0.0
    for i in range(nv):
        tot += w[vs[i]]
    acc = 0.0
    for i in range(nv):
        lw[i] = math.log(w[vs[i]] / tot)
        acc += w[vs[i]] / tot
        cw[i] = acc
    return lw, cw


@nb.njit(cache=True)
def sample_first_hits(samples: PackedSamples, rays: RayTable, c, loc, nv):
    """``nv x B`` int64: the first hit (kappa; ``len_b``: none) of every beam of candidate ``c`` in every kept
    sample (``loc`` of :func:`kept_samples`)."""
    packed, valid_mask = samples.packed, samples.valid_mask
    offsets, cells, pose_cells, B = rays.offsets, rays.cells, rays.pose_cells, rays.num_beams
    Wd = packed.shape[1]
    one = np.uint64(1)
    fh = np.empty((nv, B), np.int64)
    alive = np.empty(Wd, np.uint64)
    for b in range(B):
        r = c * B + b
        n = offsets[r + 1] - offsets[r]
        for i in range(nv):
            fh[i, b] = n
        for k in range(Wd):
            alive[k] = ~packed[pose_cells[c], k] & valid_mask[k]
        for kap in range(1, n):
            cell = cells[offsets[r] + kap]
            any_alive = False
            for k in range(Wd):
                hit = alive[k] & packed[cell, k]
                alive[k] &= ~packed[cell, k]
                while hit != 0:
                    s = k * 64 + ctz(hit)
                    if loc[s] >= 0:
                        fh[loc[s], b] = kap
                    hit &= hit - one
                if alive[k] != 0:
                    any_alive = True
            if not any_alive:
                break
    return fh


@nb.njit(cache=True)
def first_hit_groups(fh, rays: RayTable, c):
    """The distinct first hits of each beam of candidate ``c`` among the kept samples (``fh`` of
    :func:`sample_first_hits`): ``gval[b, :gnum[b]]`` the values, ``gid[i, b]`` sample ``i``'s group."""
    offsets, B = rays.offsets, rays.num_beams
    nv = fh.shape[0]
    Lmax = 0
    for b in range(B):
        Lmax = max(Lmax, offsets[c * B + b + 1] - offsets[c * B + b])
    gid = np.empty((nv, B), np.int64)
    gval = np.empty((B, nv), np.int64)
    gnum = np.zeros(B, np.int64)
    seen = np.empty(Lmax + 1, np.int64)
    for b in range(B):
        seen[:] = -1
        for i in range(nv):
            f = fh[i, b]
            if seen[f] < 0:
                seen[f] = gnum[b]
                gval[b, gnum[b]] = f
                gnum[b] += 1
            gid[i, b] = seen[f]
    return gid, gval, gnum


# cached on disk for the shipped reading kinds only (see beam_mi)
@njit_shipped
def scan_mi_kernel(samples: PackedSamples, rays: RayTable, Fray, reading, binned, draws: Draws):
    """Nested Monte-Carlo ``I(m; Z)`` in nats per candidate (module docstring): ``(mean, variance of the
    terms)``, ``C`` float64 each; a candidate whose cell is occupied in every sample gets ``nan``. ``Fray``:
    the last kappa of every ray; ``reading``: the sensor's reading bundle; ``binned``: score continuous ranges
    by their bin, not their density."""
    w = samples.w
    offsets, t_enter, pose_cells, B = rays.offsets, rays.t_enter, rays.pose_cells, rays.num_beams
    u_pick, eps, u_a, u_b = draws.u_pick, draws.eps, draws.u_a, draws.u_b
    C = pose_cells.shape[0]
    N = u_pick.shape[1]
    mean = np.full(C, np.nan)
    var = np.full(C, np.nan)
    for c in range(C):
        loc, vs, nv = kept_samples(samples, pose_cells[c])
        if nv == 0:
            continue
        lw, cw = _log_weights(w, vs, nv)
        fh = sample_first_hits(samples, rays, c, loc, nv)
        gid, gval, gnum = first_hit_groups(fh, rays, c)
        L = np.empty(nv)
        ll = np.empty(nv)
        m1 = 0.0
        m2 = 0.0
        for t in range(N):
            sn = 0
            while sn < nv - 1 and cw[sn] < u_pick[c, t]:
                sn += 1
            L[:] = 0.0
            for b in range(B):
                r = c * B + b
                n = offsets[r + 1] - offsets[r]
                F = Fray[r]
                J = num_outcomes(reading, F)
                f0 = fh[sn, b]
                none0 = f0 == n
                # draw the reading of beam b given sample sn's first hit (as SensorModel.sample does)
                fc0 = 0.0 if none0 else coord(reading, t_enter, offsets[r], f0)
                y, is_max, jb = draw(reading, J, fc0, none0, F, u_a[c, t, b], u_b[c, t, b], eps[c, t, b])
                for g in range(gnum[b]):
                    fg = gval[b, g]
                    ng = fg == n
                    fc = 0.0 if ng else coord(reading, t_enter, offsets[r], fg)
                    ll[g] = log_reading(reading, binned, y, jb, is_max, J, fc, ng, F)
                for i in range(nv):
                    L[i] += ll[gid[i, b]]
            mx = -np.inf
            for i in range(nv):
                mx = max(mx, lw[i] + L[i])
            se = 0.0
            for i in range(nv):
                se += math.exp(lw[i] + L[i] - mx)
            term = L[sn] - (mx + math.log(se))
            d = term - m1
            m1 += d / (t + 1)
            m2 += d * (term - m1)
        mean[c] = m1
        var[c] = m2 / (N - 1) if N > 1 else 0.0
    return mean, var
