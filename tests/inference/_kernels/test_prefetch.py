"""A prefetch reads and writes nothing: the kernel around it computes the same."""

from __future__ import annotations

import numba as nb
import numpy as np

from ogm_ppl.inference._kernels.prefetch import prefetch


@nb.njit(cache=False)
def _sum_with_prefetch(a, far):
    s = 0.0
    for i in range(a.shape[0]):
        prefetch(a, (i + far) % a.shape[0], 0)
        for j in range(a.shape[1]):
            s += a[i, j]
    return s


def test_prefetch_changes_nothing():
    a = np.arange(64 * 7, dtype=np.float64).reshape(64, 7)
    b = a.copy()
    assert _sum_with_prefetch(a, 5) == a.sum()
    np.testing.assert_array_equal(a, b)
