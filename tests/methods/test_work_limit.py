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


@pytest.fixture
def no_cast(problem, monkeypatch):
    """The ray cast and the model's building fail the test if reached: a refusal must come before them."""
    import importlib

    def never(*a, **k):
        raise AssertionError("the ray cast ran before the size check")

    monkeypatch.setattr(importlib.import_module("ogm_ppl.raycast"), "traverse_all", never)
    monkeypatch.setattr(problem, "_rays", None)
    return problem


@pytest.fixture
def memory(monkeypatch):
    """Pretend the machine has 8 GiB free."""
    import ogm_ppl._memory

    monkeypatch.setattr(ogm_ppl._memory, "available_memory", lambda: 8 << 30)


@pytest.mark.parametrize(
    "method, params, key, message",
    [
        (
            "vi",
            {"loss": "tracegraph", "num_particles": 1_000_000_000},
            "num_particles",
            r"1,000,000,000 particles of tracegraph \(each 96 bytes a cell and a reading: 4,096 cells \+ 135 "
            r"readings, 396\.7 KiB a particle\) needs about 378,280\.9 GiB, more than the 8\.0 GiB this machine "
            r"has free",
        ),
        (
            "vi",
            {"loss": "rws", "num_particles": 10_000, "steps": 10_000},
            "steps",
            r"10,000 steps x 10,000 particles x \(4,096 cells \+ 135 readings\) = 4\.23e\+11, over the limit of "
            r"2\^36",
        ),
        (
            "tempering",
            {"rungs": 10_000_000},
            "rungs",
            r"10,000,000 rungs of parallel tempering \(each a likelihood table of 135 rays x 59 float64 "
            r"\(62\.2 KiB\) and 64 bytes a cell for its kernel's state, 4,096 cells: 318\.2 KiB a rung\) needs "
            r"about 3,034\.8 GiB, more than the 8\.0 GiB",
        ),
        (
            "tempering",
            {"rungs": 1000, "sweeps": 1_000_000},
            "sweeps",
            r"1,000,000 sweeps \(burn-in 0 \+ 1,000,000\) x 1 chains x 1,000 maps swept \(rungs\) x 4,096 cells = "
            r"4\.1e\+12 single-cell updates, over the limit of 2\^40",
        ),
        (
            "gibbs",
            {"sweeps": 1_000_000_000, "chains": 1000},
            "sweeps",
            r"x 1,000 chains x 4,096 cells = 4\.1e\+15 single-cell updates, over the limit of 2\^40",
        ),
        ("tempering", {"rungs": 4, "patch": [5, 5], "sweeps": 100}, "patch", r"configurations, over the limit"),
    ],
)
def test_work_that_would_not_fit_is_refused_before_the_ray_cast(no_cast, memory, method, params, key, message):
    """Parameters that scale memory (particles, rungs) or time (sweeps, chains, rungs, steps): a run past the
    free memory or the time limit is refused at once, naming the parameter, the estimate with its basis, and the
    limit, before the ray cast or any allocation."""
    m = get_method(method)
    with pytest.raises(ParamError, match=message) as e:
        m.run(m.parse(params), no_cast, RunContext(seed=0))
    assert e.value.key == key


def test_sweeps_beyond_any_run_are_refused_when_parsed():
    """A sweep count past MAX_SWEEPS (or any integer past int64) is refused when the parameters are parsed, with
    the limit, not as an OverflowError at the first checkpoint."""
    from ogm_ppl.methods._sampling import MAX_SWEEPS
    from ogm_ppl.methods.params import INT_LIMIT

    m = get_method("gibbs")
    for key in ("sweeps", "burn_in", "warm_thesis"):
        with pytest.raises(ParamError, match=rf"{key}: must be <= 1000000000 \(.*MAX_SWEEPS.*\), got 9{{23}}"):
            m.parse({key: "9" * 23}, text=True)
        patch = {"patch": [3, 3]} if key == "warm_thesis" else {}
        assert getattr(m.parse({key: MAX_SWEEPS, **patch}), key) == MAX_SWEEPS
    with pytest.raises(ParamError, match=r"offset: must be at most 2\^63 - 1 = 9223372036854775807 in magnitude"):
        m.parse({"offset": INT_LIMIT + 1})


def test_more_records_than_sweeps_are_one_a_sweep(problem, tmp_path):
    """``record`` past the sweeps asked for records every counted sweep once (a record count of 10^12 does not
    loop 10^12 times)."""
    m = get_method("gibbs")
    r = m.run(m.parse({"sweeps": 4, "record": 10**12}), problem, RunContext(seed=0, checkpoint_dir=tmp_path))
    assert [t["sweep"] for t in r.details["trace"]] == [1, 2, 3, 4]
