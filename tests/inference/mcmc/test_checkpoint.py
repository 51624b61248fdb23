"""A Gibbs checkpoint resumes only the run it belongs to; unreadable checkpoints name their path."""

import numpy as np
import pytest
import torch

from ogm_ppl import GaussianRange, Grid, OccupancyModel, Scans, raycast
from ogm_ppl.datasets import THESIS_TOY_READINGS, toy_1d
from ogm_ppl.inference import CellGibbs, PatchGibbs, RunningStats, run_gibbs
from ogm_ppl.inference.mcmc.runner import CheckpointError
from ogm_ppl.priors import IndependentPrior


def _model(readings=THESIS_TOY_READINGS, lam=0.3, sigma=3.0, K=16):
    toy = toy_1d(num_cells=K, readings=readings)
    return OccupancyModel(toy.grid, raycast(toy.grid, toy.scans), GaussianRange(sigma), IndependentPrior(lam, K))


def _interrupted(tmp_path, model):
    ck = tmp_path / "ck.npz"
    run = run_gibbs(
        CellGibbs(model),
        200,
        RunningStats(model, rays=[0]),
        seed=3,
        checkpoint=ck,
        checkpoint_every=20,
        stop_after=50,
        progress=False,
    )
    assert run.interrupted and ck.exists()
    return ck


@pytest.mark.parametrize(
    "other, kernel, stats, what",
    [
        # same K, other readings: resumed silently before and mixed two posteriors
        (lambda: _model(readings=(10.0, 9.0, 9.0, 11.0, 12.0, 8.0)), None, None, "the readings or the pinned"),
        (lambda: _model(sigma=2.0), None, None, r"the likelihood table \(the sensor model"),
        (lambda: _model(lam=0.5), None, None, "the prior"),
        (lambda: _model(), lambda m: CellGibbs(m, scan="random"), None, "the kernel or its settings"),
        (lambda: _model(), lambda m: PatchGibbs(m, 3), None, "the kernel"),
        (lambda: _model(), None, lambda m: RunningStats(m, rays=[0], pairs=[[3, 4]]), "the tracked statistics"),
    ],
)
def test_checkpoint_of_another_run_is_refused(tmp_path, other, kernel, stats, what):
    ck = _interrupted(tmp_path, _model())
    m = other()
    k = kernel(m) if kernel else CellGibbs(m)
    s = stats(m) if stats else RunningStats(m, rays=[0])
    with pytest.raises(CheckpointError, match=rf"ck\.npz: checkpoint belongs to another run; what differs .*{what}"):
        run_gibbs(k, 200, s, seed=3, checkpoint=ck, progress=False)
    # the same run still resumes
    m0 = _model()
    done = run_gibbs(CellGibbs(m0), 200, RunningStats(m0, rays=[0]), seed=3, checkpoint=ck, progress=False)
    assert done.sweeps == 200 and not done.interrupted


@pytest.mark.parametrize(
    "content",
    [b"", b"not a zip at all", b"PK\x03\x04 truncated", "truncate", "foreign", "pickled"],
)
def test_unreadable_checkpoint_names_the_path(tmp_path, content):
    model = _model()
    ck = tmp_path / "bad.npz"
    if content == "truncate":
        good = _interrupted(tmp_path, model)
        ck.write_bytes(good.read_bytes()[:300])
    elif content == "foreign":
        np.savez(ck, weights=np.ones(3))
    elif content == "pickled":
        np.savez(ck, format=np.array([{"a": 1}], dtype=object))
    else:
        ck.write_bytes(content)
    with pytest.raises(CheckpointError, match=r"bad\.npz: .*(start a fresh run)"):
        run_gibbs(CellGibbs(model), 100, RunningStats(model), seed=3, checkpoint=ck, progress=False)


@pytest.mark.parametrize("a, b", [("border:generated", "border:houseexpo"), ("patch3:generated", "patch3:houseexpo")])
def test_prior_fingerprint_sees_the_tables(a, b):
    """Two table priors of one kind from different corpora: every seeded random test map may score
    ``-inf`` under both, but their tables differ, and so do the fingerprints."""
    from ogm_ppl.inference.mcmc.fingerprint import fingerprint
    from ogm_ppl.priors.named import prior_by_name

    fps = []
    for name in (a, b, a):
        prior = prior_by_name(name, (6, 6))
        grid = Grid((6, 6), 1.0)
        scans = Scans(torch.tensor([[2.5, 2.5, 0.0]]), torch.tensor([[0.0, 1.5]]), torch.tensor([[2.0, 2.5]]), 5.0)
        model = OccupancyModel(grid, raycast(grid, scans), GaussianRange(3.0), prior)
        fps.append(fingerprint(CellGibbs(model), RunningStats(model))["prior"])
    assert fps[0] != fps[1] and fps[0] == fps[2]


def test_a_checkpoint_past_the_sweeps_asked_for_is_refused(tmp_path):
    """A finished checkpoint extends to more sweeps; asked for fewer than it holds it cannot go back, and says so
    instead of returning its longer run."""
    model = _model()
    ck = tmp_path / "ck.npz"
    run_gibbs(
        CellGibbs(model), 60, warmup=10, seed=3, checkpoint=ck, checkpoint_every=10, stop_after=50, progress=False
    )
    with pytest.raises(
        CheckpointError, match=r"ck\.npz: checkpoint holds 50 sweeps \(warm-up included\), more than the 40"
    ):
        run_gibbs(CellGibbs(model), 30, warmup=10, seed=3, checkpoint=ck, progress=False)
    assert run_gibbs(CellGibbs(model), 60, warmup=10, seed=3, checkpoint=ck, progress=False).sweeps == 70


def test_resume_with_another_warmup_is_refused(tmp_path):
    model = _model()
    ck = tmp_path / "ck.npz"
    run_gibbs(
        CellGibbs(model), 50, warmup=30, seed=3, checkpoint=ck, checkpoint_every=10, stop_after=20, progress=False
    )
    with pytest.raises(CheckpointError, match=r"ck\.npz: checkpoint was written with warmup 30, not 0"):
        run_gibbs(CellGibbs(model), 50, warmup=0, seed=3, checkpoint=ck, progress=False)
    r = run_gibbs(CellGibbs(model), 50, warmup=30, seed=3, checkpoint=ck, progress=False)
    assert r.sweeps == 80 and r.stats.n == 50


class _Counting(CellGibbs):
    """A subclass keeping a public counter that its sweeps update (as a user's kernel may)."""

    def __init__(self, model) -> None:
        super().__init__(model)
        self.visits = 0

    def _sweep(self) -> int:
        self.visits += 1
        return super()._sweep()


def test_a_public_counter_does_not_make_the_same_chain_look_like_another(tmp_path):
    """The kernel's settings are read once, as built: the chain's own later calls (one a record mark, as a
    map method runs it) and a new process's kernel resume its checkpoint; a changed setting is still refused."""
    model = _model()
    ck = tmp_path / "ck.npz"
    full = run_gibbs(_Counting(model), 60, seed=3, progress=False)
    k = _Counting(model)
    a = run_gibbs(k, 60, seed=3, checkpoint=ck, stop_after=20, progress=False)
    assert a.interrupted and k.visits == 20
    b = run_gibbs(k, 60, seed=3, checkpoint=ck, stop_after=20, progress=False)  # the same object goes on
    assert b.sweeps == 40
    c = run_gibbs(_Counting(model), 60, seed=3, checkpoint=ck, progress=False)  # a new process's kernel
    assert c.sweeps == 60 and torch.equal(c.stats.marginals, full.stats.marginals)
    other = _Counting(model)
    other.scan = "random"
    run_gibbs(_Counting(model), 60, seed=3, checkpoint=tmp_path / "d.npz", stop_after=5, progress=False)
    with pytest.raises(CheckpointError, match="the kernel or its settings"):
        run_gibbs(other, 60, seed=3, checkpoint=tmp_path / "d.npz", progress=False)


def _edited(ck, **fields):
    """``ck`` rewritten with ``fields`` changed (a function of the stored array, or a new array)."""
    with np.load(ck, allow_pickle=False) as z:
        d = {k: z[k] for k in z.files}
    for k, f in fields.items():
        d[k] = f(d[k].copy()) if callable(f) else f
    np.savez(ck, **d)


def _set(i, v):
    def edit(a):
        a[i] = v
        return a

    return edit


@pytest.mark.parametrize(
    "fields, message",
    [
        ({"stats_sum": _set(3, np.nan)}, r"field stats_sum\[3\] is nan: a running sum must be finite"),
        ({"stats_sum": _set(5, np.inf)}, r"field stats_sum\[5\] is inf: a running sum must be finite"),
        ({"stats_sum": _set(2, -1.0)}, r"field stats_sum\[2\] is -1.0, outside the whole counts 0..30"),
        ({"stats_sum": _set(0, 31.0)}, r"field stats_sum\[0\] is 31.0, outside the whole counts 0..30"),
        ({"stats_sum": _set(1, 0.5)}, r"field stats_sum\[1\] is 0.5, outside the whole counts"),
        ({"stats_sum": np.zeros(3)}, r"field stats_sum has shape \(3,\), this run's statistics \(16,\)"),
        ({"stats_fh0": _set(0, np.nan)}, r"field stats_fh0\[0\] is nan"),
        ({"stats_fh0": lambda a: a + 1}, r"field stats_fh0 counts \d+ first hits, not one for each of the 30 samples"),
        ({"stats_trace": _set((0, 0), 2)}, r"field stats_trace holds a value other than 0 and 1"),
        ({"stats_trace": np.zeros((4, 1), np.uint8)}, r"field stats_trace has shape \(4, 1\), not one row"),
        ({"stats_n": np.int64(-1)}, r"field stats_n is -1, not a count"),
        ({"stats_n": np.float64(30.5)}, r"field stats_n is 30.5, not a count"),
        ({"sweep": np.int64(-5)}, r"field sweep is -5, not a count"),
    ],
)
def test_a_checkpoint_with_impossible_statistics_is_refused_naming_the_field(tmp_path, fields, message):
    """Running sums that hold NaN or infinity, counts outside ``[0, n]``, fields of another shape or a negative
    count cannot come from a run: resuming is refused naming the file and the field (a NaN resumed would spread
    into the map)."""
    model = _model()
    ck = tmp_path / "ck.npz"
    run_gibbs(
        CellGibbs(model),
        200,
        RunningStats(model, rays=[0], trace_cells=[4]),
        warmup=20,
        seed=3,
        checkpoint=ck,
        stop_after=50,
        progress=False,
    )
    _edited(ck, **fields)
    with pytest.raises(CheckpointError, match=rf"ck\.npz: {message}") as e:
        run_gibbs(
            CellGibbs(model),
            200,
            RunningStats(model, rays=[0], trace_cells=[4]),
            warmup=20,
            seed=3,
            checkpoint=ck,
            progress=False,
        )
    assert "start a fresh run" in str(e.value)


def test_a_checkpoint_written_to_a_full_disk_names_the_file_and_keeps_the_previous_one(tmp_path, monkeypatch):
    """Disk full at a checkpoint: the error names the checkpoint (not a bare ``[Errno 28]``); the previous
    checkpoint is left whole and resumes the chain afterwards, bit for bit."""
    import errno

    from tests._faults import full_disk

    model = _model()
    ck = _interrupted(tmp_path, model)
    before = ck.read_bytes()
    with monkeypatch.context() as mp:
        full_disk(mp)
        with pytest.raises(OSError, match="No space left on device") as e:
            run_gibbs(
                CellGibbs(model),
                200,
                RunningStats(model, rays=[0]),
                seed=3,
                checkpoint=ck,
                checkpoint_every=20,
                progress=False,
            )
    assert e.value.errno == errno.ENOSPC and e.value.filename == str(ck)
    assert ck.read_bytes() == before and sorted(p.name for p in tmp_path.iterdir()) == ["ck.npz"]
    full = run_gibbs(CellGibbs(model), 200, RunningStats(model, rays=[0]), seed=3, progress=False)
    done = run_gibbs(CellGibbs(model), 200, RunningStats(model, rays=[0]), seed=3, checkpoint=ck, progress=False)
    assert torch.equal(done.stats.marginals, full.stats.marginals)
