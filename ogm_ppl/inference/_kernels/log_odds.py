"""Numba kernels for the evidence-grid update of traditional OGM (Eq. 2.10)."""

from __future__ import annotations

import numba as nb
import numpy as np

from ogm_ppl._raycast_kernels import ray_capacity, trace_ray


@nb.njit(cache=True)
def evidence_update(evidence, touched, offsets, cells, z, is_max, table, max_col, lo, hi, clamp):
    """Add ``table[kappa, z_n]`` to every cell of every ray, in reading order, in place.

    With ``clamp`` the log-odds are clipped to ``[lo, hi]`` after each update (OctoMap's convention).
    ``touched`` records cells that received a non-zero update.
    """
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
def evidence_from_scans(
    u0, v0, du, dv, length, t_hit, is_max, rows, cols, evidence, touched, table, max_col, lo, hi, clamp
):
    """Fused traversal and update: each ray is walked into a scratch buffer and applied at once,
    without materialising the CSR structure (same cells, same order, same numbers)."""
    R = u0.shape[0]
    cap = 1
    for r in range(R):
        cap = max(cap, ray_capacity(length[r], du[r], dv[r]))
    buf_cells = np.empty(cap, np.int64)
    buf_t = np.empty(cap, np.float32)
    n_rows = table.shape[0]
    for r in range(R):
        n, zr, _ = trace_ray(
            u0[r], v0[r], du[r], dv[r], length[r], t_hit[r], is_max[r], rows, cols, buf_cells, buf_t, 0, False
        )
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
