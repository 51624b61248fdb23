"""The gibbs method's ``warm_thesis`` start (an exact patch chain started where sweeps of the thesis's border
update end: reproducible from the seed, refused where it means nothing) and its ``cell_sweeps`` cycle."""

from __future__ import annotations

import numpy as np
import pytest

from ogm_ppl.methods import RunContext, get_method
from ogm_ppl.methods.params import ParamError

from .test_registry import box  # noqa: F401  (the fixture)

BORDER = {"prior": "border_bo:generated", "patch": [3, 3], "sweeps": 3, "burn_in": 0}


def test_warm_thesis_starts_the_exact_chain_from_the_thesis_update(box, monkeypatch):  # noqa: F811
    from ogm_ppl.inference.mcmc import PatchGibbs

    _, problem = box
    method = get_method("gibbs")
    warm = method.parse({**BORDER, "warm_thesis": 4})
    a = method.run(warm, problem, RunContext(seed=5)).probabilities
    b = method.run(warm, problem, RunContext(seed=5)).probabilities
    cold = method.run(method.parse(BORDER), problem, RunContext(seed=5)).probabilities
    assert np.array_equal(a, b) and not np.array_equal(a, cold)
    # the exact kernel's starting map is the thesis kernel's state after the warm sweeps
    made = []
    import ogm_ppl.inference.mcmc as mcmc

    monkeypatch.setattr(mcmc, "PatchGibbs", lambda *a, **kw: made.append(PatchGibbs(*a, **kw)) or made[-1])
    method.run(warm, problem, RunContext(seed=5))
    thesis, exact = made
    assert thesis.update == "thesis" and exact.update == "gibbs"
    start = exact._initial_map().numpy()
    assert start.shape == (problem.grid.num_cells,)
    assert np.array_equal(start, thesis.state.astype(np.float64))


@pytest.mark.parametrize(
    "values",
    [
        {"warm_thesis": 2, "patch": 1},
        {"warm_thesis": 2, "patch": [3, 3], "update": "thesis"},
        {"cell_sweeps": True, "patch": 1},
        {"cell_sweeps": True, "patch": [3, 3], "update": "thesis"},
    ],
)
def test_warm_thesis_and_cell_sweeps_are_refused_where_they_mean_nothing(values):
    name = "warm_thesis" if "warm_thesis" in values else "cell_sweeps"
    with pytest.raises(ParamError, match=name):
        get_method("gibbs").parse(values)


def test_cell_sweeps_cycle_patch_and_cell_gibbs_and_resume_from_a_checkpoint(box, tmp_path):  # noqa: F811
    """``cell_sweeps``: each sweep is a patch sweep and a cell sweep (both parts sweep as often as the chain);
    a run stopped half way resumes from its checkpoint to the very marginals of an uninterrupted run."""
    _, problem = box
    method = get_method("gibbs")
    p = method.parse({**BORDER, "cell_sweeps": True, "sweeps": 6, "burn_in": 2})
    full = method.run(p, problem, RunContext(seed=3))
    assert full.details["kernel"] == "KernelCycle(PatchGibbs, CellGibbs)"
    plain = method.run(method.parse({**BORDER, "sweeps": 6, "burn_in": 2}), problem, RunContext(seed=3))
    assert not np.array_equal(full.probabilities, plain.probabilities)
    ctx = dict(seed=3, checkpoint_dir=tmp_path / "ck")
    half = method.run(p, problem, RunContext(**ctx, stop_after=4))
    assert half.probabilities is None
    resumed = method.run(p, problem, RunContext(**ctx, resume=True))
    np.testing.assert_array_equal(resumed.probabilities, full.probabilities)
    # the records' clock counts the stopped call's sampling too (kept in the checkpoint)
    before = resumed.details["resumed_seconds"]
    assert before > 0 and resumed.details["trace"][-1]["seconds"] > before


def test_a_checkpoint_of_another_length_resumes_on_this_runs_schedule(box, tmp_path):  # noqa: F811
    """The same chain asked for another length reuses the checkpoint where it can (a shorter stopped run goes
    on) and starts afresh where it cannot (a checkpoint past the sweeps now asked for); either way its records
    sit at the marks of the run asked for (those it passed before the resume are not made up) and its map is
    that of an uninterrupted run."""
    _, problem = box
    method = get_method("gibbs")
    ctx = dict(seed=3, checkpoint_dir=tmp_path / "ck")
    long = method.parse({**BORDER, "sweeps": 40, "burn_in": 0, "record": 4, "checkpoint_every": 2})
    short = method.parse({**BORDER, "sweeps": 12, "burn_in": 0, "record": 4, "checkpoint_every": 2})
    fresh = method.run(short, problem, RunContext(seed=3))
    assert method.run(long, problem, RunContext(**ctx, stop_after=22)).probabilities is None  # recorded 10, 20
    r = method.run(short, problem, RunContext(**ctx))  # 22 > 12: cannot go back
    assert [t["sweep"] for t in r.details["trace"]] == [3, 6, 9, 12]
    np.testing.assert_array_equal(r.probabilities, fresh.probabilities)
    (tmp_path / "ck" / "gibbs.npz").unlink()
    assert method.run(long, problem, RunContext(**ctx, stop_after=11)).probabilities is None  # recorded 10
    mid = method.parse({**BORDER, "sweeps": 24, "burn_in": 0, "record": 4, "checkpoint_every": 2})
    r = method.run(mid, problem, RunContext(**ctx))
    assert [t["sweep"] for t in r.details["trace"]] == [12, 18, 24]  # the longer run's record at 10 is dropped
    np.testing.assert_array_equal(r.probabilities, method.run(mid, problem, RunContext(seed=3)).probabilities)


@pytest.mark.parametrize(
    "method_name, params, checkpointed",
    [
        ("gibbs", {"sweeps": 30, "burn_in": 5}, True),
        ("gibbs", {"sweeps": 30, "burn_in": 5}, False),
        ("vi", {"steps": 30}, False),
    ],
)
def test_a_labelled_run_shows_plain_progress_lines_once_long(
    box,  # noqa: F811
    monkeypatch,
    capsys,
    tmp_path,
    method_name,
    params,
    checkpointed,
):
    """An experiment's task labels its run: past 10 s (a clock that moves a second a call here) it prints plain
    lines naming the run, never a bar, whatever stderr is; a checkpointed chain's calls (one a record mark)
    share them."""
    _, problem = box
    clock = iter(range(10**6))
    monkeypatch.setattr("ogm_ppl.progress.time.perf_counter", lambda: float(next(clock)))
    monkeypatch.setattr("ogm_ppl.progress.interactive", lambda stream=None: True)  # as on a terminal
    method = get_method(method_name)
    ckpt = {"checkpoint_dir": tmp_path / "ck"} if checkpointed else {}
    ctx = RunContext(seed=1, progress=True, label="office/x/c0", **ckpt)
    method.run(method.parse(params), problem, ctx)
    lines = capsys.readouterr().err.splitlines()
    what = "gibbs sweeps" if method_name == "gibbs" else "svi steps"
    assert lines and all(line.startswith(f"office/x/c0: {what}: ") for line in lines), lines
    assert lines[-1].endswith(", done") and len(lines) >= 3


def test_gibbs_on_threads_is_one_chain_whatever_the_number_and_targets_the_posterior():
    """``threads = N``: the chromatic kernels, whose chain does not depend on ``N`` (bit for bit); the serial
    kernel's chain is another, and both estimate the same brute-force marginals."""
    from ogm_ppl.inference.exact import brute_force
    from ogm_ppl.inference.mcmc.parallel import max_threads
    from ogm_ppl.methods import MapProblem, RunContext, get_method
    from ogm_ppl.testing.kernels import enumerable_2d_data

    problem = MapProblem(*enumerable_2d_data(), 0.9)
    gibbs = get_method("gibbs")
    exact = brute_force(problem.model()).marginals.numpy()
    runs = {}
    for threads in (None, 1, max_threads()):
        for patch in (1, [2, 2]):
            p = gibbs.parse({"sweeps": 4000, "burn_in": 100, "threads": threads, "patch": patch})
            r = gibbs.run(p, problem, RunContext(seed=5))
            runs[threads, str(patch)] = r
            # a cell's mean over 4,000 sweeps: at most 0.5 / sqrt(4000) = 0.008 standard error were the sweeps
            # uncorrelated; 0.05 leaves room for an autocorrelation time of about 1.5 at 5 standard errors
            np.testing.assert_allclose(r.probabilities, exact, atol=0.05)
    for patch in ("1", "[2, 2]"):
        assert np.array_equal(runs[1, patch].probabilities, runs[max_threads(), patch].probabilities)
        assert not np.array_equal(runs[None, patch].probabilities, runs[1, patch].probabilities)
    assert runs[1, "1"].details["kernel"] == "ChromaticCellGibbs" and runs[1, "1"].details["threads"] == 1
    assert runs[1, "[2, 2]"].details["kernel"] == "ChromaticPatchGibbs"
    assert runs[None, "1"].details["kernel"] == "CellGibbs" and "threads" not in runs[None, "1"].details


def test_gibbs_threads_are_checked():
    from ogm_ppl.inference.mcmc.parallel import max_threads
    from ogm_ppl.methods import ParamError, get_method

    gibbs = get_method("gibbs")
    with pytest.raises(ParamError, match="at most numba's"):
        gibbs.parse({"threads": max_threads() + 1})
    with pytest.raises(ParamError, match="systematic or permutation"):
        gibbs.parse({"threads": 1, "patch": [2, 2], "scan": "random"})
    with pytest.raises(ParamError):
        gibbs.parse({"threads": 0})


@pytest.mark.parametrize("patch", [1, [2, 2]])
def test_a_chain_runs_under_the_shipped_net_field(patch):
    """``net:houseexpo`` is a prior name like any other: the gibbs method's cell and patch chains run under it on
    a small room at the corpus's 5 cm cells, reproducibly from the seed, and keep the cells the scans saw."""
    from ogm_ppl.datasets.stop_and_scan import stop_and_scan
    from ogm_ppl.grid import Grid
    from ogm_ppl.methods import MapProblem

    truth = np.zeros((14, 14), bool)
    truth[:2, :] = truth[-2:, :] = truth[:, :2] = truth[:, -2:] = True
    grid = Grid(truth.shape, 0.05)
    route = np.array([[0.35, 0.35, 0.0]])
    data = stop_and_scan(truth, grid, route=route, beams=72, max_range_cells=20, sigma_cells=0.5, seed=0)
    problem = MapProblem(grid, data.scans, sigma_cells=0.5)
    method = get_method("gibbs")
    p = method.parse({"prior": "net:houseexpo", "patch": patch, "sweeps": 3, "burn_in": 1})
    a = method.run(p, problem, RunContext(seed=2)).probabilities
    b = method.run(p, problem, RunContext(seed=2)).probabilities
    assert np.array_equal(a, b) and a.shape == (grid.num_cells,)
    assert np.all((a >= 0) & (a <= 1))
    m = a.reshape(truth.shape)
    assert m[5:9, 5:9].max() < 0.5 and m[1, 4:10].mean() > 0.5  # the room's middle free, its wall face occupied
