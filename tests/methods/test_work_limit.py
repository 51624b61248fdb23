"""Patch methods refuse runs that would enumerate more configurations than the stated limit."""

import time

import numpy as np
import pytest

from ogm_ppl.datasets.simple2d import simple_2d_example
from ogm_ppl.methods import MapProblem, ParamError, RunContext, get_method
from ogm_ppl.methods._model import MAX_PATCH_CONFIGURATIONS, check_patch_work


@pytest.fixture(scope="module")
def problem():
    ex = simple_2d_example(num_beams=45)  # 64 x 64 cells
    return MapProblem(ex.grid, ex.scans, sigma_cells=3.0)


@pytest.mark.parametrize(
    "method, params",
    [("gibbs", {"patch": [4, 5], "sweeps": 100}), ("patch", {"patch": [5, 5]})],
)
def test_hours_of_patch_work_refused_at_once(problem, method, params):
    """64 x 64 cells: PatchGibbs with 4 x 5 patches for 100 sweeps is 205 x 2^20 x 100 = 2.2e10
    configurations (about 24 minutes); the overlapping 5 x 5 patch map 4096 x 2^25 = 1.4e11. Both are refused
    before any work, naming the limit."""
    m = get_method(method)
    t0 = time.monotonic()
    with pytest.raises(ParamError, match=r"patch: .* configurations, over the limit of 2\^33") as e:
        m.run(m.parse(params), problem, RunContext(seed=0))
    assert time.monotonic() - t0 < 5 and e.value.key == "patch"


def test_limit_arithmetic():
    K = 64 * 64
    check_patch_work([3, 3], 2, K, 1000, False, "x")  # 456 x 512 x 1000 = 2.3e8: allowed
    check_patch_work([4, 4], 2, K, 1, True, "x")  # 4096 x 65536 = 2.7e8: allowed
    L = 20
    passes = int(np.ceil(MAX_PATCH_CONFIGURATIONS / (-(-K // L) * 2**L))) + 1
    with pytest.raises(ParamError, match=rf"x {passes} ="):
        check_patch_work([4, 5], 2, K, passes, False, "x")
    check_patch_work([4, 5], 2, K, passes - 2, False, "x")
