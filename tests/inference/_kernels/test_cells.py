"""The compiled cell helpers: the gathered sample equals numpy's fancy index."""

import numpy as np

from ogm_ppl.inference._kernels.cells import gather_as_float


def test_gather_as_float_equals_the_fancy_index():
    rng = np.random.default_rng(0)
    m = rng.integers(0, 2, 1000).astype(np.uint8)
    for idx in (np.arange(1000), np.sort(rng.choice(1000, 950, replace=False)), np.zeros(0, np.int64)):
        out = gather_as_float(m, idx.astype(np.int64))
        assert out.dtype == np.float64 and np.array_equal(out, m[idx].astype(np.float64))
