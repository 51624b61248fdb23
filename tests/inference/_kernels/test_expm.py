"""The choice step's vectorisable ``exp`` against numpy's, over its whole domain."""

from __future__ import annotations

import numba as nb
import numpy as np

from ogm_ppl.inference._kernels.expm import exp_nonpos

ULP = np.finfo(np.float64).eps


@nb.njit(cache=False)
def _apply(x, out):
    for j in range(x.shape[0]):
        out[j] = exp_nonpos(x[j])


def _exp(x):
    out = np.empty_like(x)
    _apply(x, out)
    return out


def test_relative_error_is_about_one_ulp_on_the_normal_range():
    rng = np.random.default_rng(0)
    x = np.concatenate([-rng.random(200_000) * 708.0, -rng.random(200_000), -rng.random(1000) * 1e-12, [0.0, -708.0]])
    got, ref = _exp(x), np.exp(x)
    rel = np.abs(got - ref) / ref
    assert rel.max() <= 2 * ULP, rel.max()
    assert got[-2] == 1.0  # exp(0) exactly: the heaviest configuration weighs 1


def test_below_the_normal_range_and_non_numbers_give_zero():
    x = np.array([-708.5, -745.2, -1e300, -np.inf, np.nan])
    np.testing.assert_array_equal(_exp(x), 0.0)


def test_monotone_on_a_fine_grid():
    x = np.linspace(-50.0, 0.0, 200_001)
    assert (np.diff(_exp(x)) >= 0).all()
