"""Numba kernels for the evidence-grid update of traditional OGM (Eq. 2.10)."""

from __future__ import annotations

import numba as nb
import numpy as np


@nb.njit(cache=True)
def evidence_update(evidence, touched, offsets, cells, z, is_max, table, max_col, lo, hi, clamp):
    """Add ``table[kappa, z_n]`` to every cell of every ray, in reading order, in place.

    With ``clamp`` the log-odds are clipped to ``[lo, hi]`` after each update (OctoMap's convention).
    ``touched`` records cells that received a non-zero update.
    """
    R = offsets.shape[0] - 1
    for r in range(R):
        col = max_col if is_max[r] else z[r]
        a = offsets[r]
        for j in range(offsets[r + 1] - a):
            d = table[j, col]
            if d != 0.0:
                c = cells[a + j]
                v = evidence[c] + d
                if clamp:
                    v = min(max(v, lo), hi)
                evidence[c] = v
                touched[c] = True
