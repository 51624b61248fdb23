"""Numba kernels for the evidence-grid update of traditional OGM (Eq. 2.10)."""

from __future__ import annotations

from typing import NamedTuple

import numba as nb
import numpy as np

from ogm_ppl._numba_cache import njit_shipped
from ogm_ppl._raycast_kernels import _axis_setup, _t_cross, ray_capacity, trace_ray
from ogm_ppl.inference._kernels.parallel import fetch_add


class EvidenceRule(NamedTuple):
    """The update term of Eq. 2.10 and its clipping (one numba argument)."""

    table: np.ndarray  # rows x cols float64: the term table[kappa, z] a ray adds to its kappa-th cell
    max_col: int  # the column of a max-range reading
    lo: float  # clip bounds of the log-odds (used only with clamp)
    hi: float
    clamp: bool  # clip to [lo, hi] after each update (OctoMap's convention)


@nb.njit(cache=True)
def evidence_update(evidence, touched, offsets, cells, z, is_max, rule):
    """Add ``rule.table[kappa, z_n]`` to every cell of every ray, in reading order, in place.

    With ``rule.clamp`` the log-odds are clipped to ``[rule.lo, rule.hi]`` after each update (OctoMap's
    convention). ``touched`` records cells that received a non-zero update.
    """
    table, max_col, lo, hi, clamp = rule
    R = offsets.shape[0] - 1
    n_rows = table.shape[0]
    for r in range(R):
        col = max_col if is_max[r] else z[r]
        a = offsets[r]
        for j in range(min(offsets[r + 1] - a, n_rows)):
            d = table[j, col]
            if d != 0.0:
                c = cells[a + j]
                v = evidence[c] + d
                if clamp:
                    v = min(max(v, lo), hi)
                evidence[c] = v
                touched[c] = True


@nb.njit(cache=True)
def evidence_from_scans(rays, rows, cols, evidence, touched, rule):
    """Fused traversal and update: each ray of ``rays`` (:class:`~ogm_ppl._raycast_kernels.RayArrays`) is
    walked into a scratch buffer and applied at once by ``rule`` (:class:`EvidenceRule`), without
    materialising the CSR structure (same cells, same order, same numbers as :func:`evidence_update`)."""
    table, max_col, lo, hi, clamp = rule
    length, du, dv, is_max = rays.length, rays.du, rays.dv, rays.is_max
    R = length.shape[0]
    cap = 1
    for r in range(R):
        cap = max(cap, ray_capacity(length[r], du[r], dv[r]))
    buf_cells = np.empty(cap, np.int64)
    buf_t = np.empty(cap, np.float32)
    n_rows = table.shape[0]
    for r in range(R):
        n, zr, _ = trace_ray(rays, r, rows, cols, buf_cells, buf_t, 0, False)
        col = max_col if is_max[r] else zr
        for j in range(min(n, n_rows)):
            d = table[j, col]
            if d != 0.0:
                c = buf_cells[j]
                v = evidence[c] + d
                if clamp:
                    v = min(max(v, lo), hi)
                evidence[c] = v
                touched[c] = True


class FixedRule(NamedTuple):
    """The update term of Eq. 2.10 in fixed point, for the threaded fused pass (one numba argument)."""

    table: np.ndarray  # cols x rows x 2 int64: a term as hi 2^-bits + lo 2^-(bits + lo_bits) (log_odds.maps);
    # column-major, so that a ray reads its column's terms from consecutive memory
    nonzero: np.ndarray  # cols x rows bool: the float term is not 0 (the cells it marks touched)
    stop: np.ndarray  # cols int64: rows of a column up to its last non-zero term (the walk stops there)
    max_col: int  # the column of a max-range reading


@nb.njit(cache=True)
def _walk_apply(rays, r, rows, cols, buf, rule, acc, touched):
    """Walk ray ``r`` as :func:`~ogm_ppl._raycast_kernels.trace_ray` does (the same cells in the same order and
    the same reading kappa), stopping once the cells left have no term (past the last non-zero row of the ray's
    column: a hit ray's cells behind its reading under Hähnel's term), and add its fixed-point terms to ``acc``."""
    table, nonzero, stop_at, max_col = rule
    u0, v0, du, dv = rays.u0[r], rays.v0[r], rays.du[r], rays.dv[r]
    L, th, mx = rays.length[r], rays.t_hit[r], rays.is_max[r]
    col, sx, bx = _axis_setup(u0, du)
    row, sy, by = _axis_setup(v0, dv)
    tx = _t_cross(bx, u0, du, sx)
    ty = _t_cross(by, v0, dv, sy)
    # the crossings after the next, computed a step ahead (the same formula and values as trace_ray's, so the
    # same cells; the division then leaves the chain of dependent steps)
    tx2 = _t_cross(bx + sx, u0, du, sx)
    ty2 = _t_cross(by + sy, v0, dv, sy)
    n = 0
    k = 0
    t = 0.0
    t_prev = 0.0
    zr = -1
    inside = True
    final = mx  # the ray's column is known (a max-range ray's from the start; a hit's once past its reading)
    n_rows = table.shape[1]
    stop = stop_at[max_col] if mx else n_rows
    while True:
        if inside:
            buf[n] = row * cols + col
            n += 1
        if not mx and not final:
            if k == 0 or 0.5 * (t_prev + t) < th:
                zr = k
            else:
                final = True
                stop = stop_at[zr]
        if final and n >= stop:
            break
        t_prev = t
        if tx <= ty:
            t = tx
            col += sx
            bx += sx
            tx = tx2
            tx2 = _t_cross(bx + sx, u0, du, sx)
        else:
            t = ty
            row += sy
            by += sy
            ty = ty2
            ty2 = _t_cross(by + sy, v0, dv, sy)
        if t >= L:
            break
        k += 1
        if inside and (col < 0 or col >= cols or row < 0 or row >= rows):
            inside = False
        if not inside and (mx or 0.5 * (t_prev + t) >= th):
            break
    terms, marks = table[max_col if mx else zr], nonzero[max_col if mx else zr]
    for j in range(min(n, n_rows)):
        if marks[j]:
            c = buf[j]
            acc[c, 0] += terms[j, 0]
            acc[c, 1] += terms[j, 1]
            touched[c] = True


_CHUNK = 1024  # rays a worker takes at a time


@njit_shipped(parallel=True)
def evidence_fixed_point(rays, rows, cols, acc, touched, rule):
    """The fused traversal and update in fixed point on ``acc.shape[0]`` workers side by side (``numba.prange``):
    each takes chunks of :data:`_CHUNK` rays from a shared counter (:func:`~.parallel.fetch_add`) while any is
    left, so a worker slowed by other jobs takes fewer, and adds their integer terms to its own ``acc[p]``
    (``P x K x 2`` int64) and marks ``touched[p]``. Integer sums do not depend on their order, so ``acc.sum(0)``
    is the same whoever took which chunk, for any number of workers."""
    P = acc.shape[0]
    R = rays.length.shape[0]
    cap = 1
    for r in range(R):
        cap = max(cap, ray_capacity(rays.length[r], rays.du[r], rays.dv[r]))
    n_chunks = (R + _CHUNK - 1) // _CHUNK
    taken = np.zeros(1, np.int64)
    for p in nb.prange(P):
        buf = np.empty(cap, np.int64)
        j = fetch_add(taken, 0, np.int64(1))
        while j < n_chunks:
            for r in range(j * _CHUNK, min(R, (j + 1) * _CHUNK)):
                _walk_apply(rays, r, rows, cols, buf, rule, acc[p], touched[p])
            j = fetch_add(taken, 0, np.int64(1))
