"""Numba kernels for the evidence-grid update of traditional OGM (Eq. 2.10)."""

from __future__ import annotations

from typing import NamedTuple

import numba as nb
import numpy as np

from ogm_ppl._raycast_kernels import ray_capacity, trace_ray


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
