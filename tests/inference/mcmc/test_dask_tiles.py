"""Chromatic tile sweeps on dask (:mod:`ogm_ppl.inference.mcmc.dask_tiles`): the tile tasks give the threaded
chromatic chain bit for bit (every scan, both updates, independent / MRF / two-scale pattern-field priors),
for 1 and 2 worker processes; the driver's kept sums stay exact; long runs match brute-force marginals; the
limits are refused with a clear error."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from ogm_ppl.inference.mcmc.dask_tiles import DaskTileGibbs, run_tile, tile_problems, window_prior
from ogm_ppl.inference.mcmc.parallel import ChromaticCellGibbs
from ogm_ppl.priors import MRFPrior, PatchTablePrior, PatternFieldPrior
from ogm_ppl.priors.pattern_field import symmetry_orbits
from tests.inference.mcmc.test_parallel import assert_long_run_matches_brute_force, scene, short_rays

distributed = pytest.importorskip("distributed")


@pytest.fixture(scope="module")
def client():
    """An in-process cluster (threads): the tasks' arithmetic is the same as on worker processes."""
    with distributed.Client(processes=False, n_workers=2, threads_per_worker=1, dashboard_address=None) as c:
        yield c


def pattern_field(n: int, seed: int = 1) -> PatternFieldPrior:
    k = symmetry_orbits(3)[1]
    rng = np.random.default_rng(seed)
    return PatternFieldPrior((n, n), rng.normal(0, 0.5, k), 3, rng.normal(0, 0.5, k))


def priors(n: int):
    return {"independent": None, "mrf8": MRFPrior((n, n), order=2, psi=0.4, cell_prior=0.3), "field2": pattern_field(n)}


def chain(kernel, sweeps: int, start: torch.Tensor, seed: int) -> list[np.ndarray]:
    kernel.setup()
    kernel.set_state(start)
    torch.manual_seed(seed)
    out = []
    for _ in range(sweeps):
        kernel.step()
        out.append(kernel.state.copy())
    return out


@pytest.mark.parametrize("name", ["independent", "mrf8", "field2"])
@pytest.mark.parametrize(
    "scan, update, tile, per_task",
    [("systematic", "gibbs", None, 1), ("permutation", "metropolised", 7, 3), ("random", "gibbs", 6, 1)],
)
def test_tile_tasks_give_the_chromatic_chain_bit_for_bit(client, name, scan, update, tile, per_task):
    n = 30
    model = scene(n=n, rmax=4.0, prior=priors(n)[name])
    ref = ChromaticCellGibbs(model, scan=scan, update=update, tile=tile, threads=1)
    dask = DaskTileGibbs(model, scan=scan, update=update, tile=tile, client=client, tiles_per_task=per_task)
    ref.setup()
    start = torch.from_numpy(ref.state.astype(np.float64))
    a = chain(ref, 4, start, seed=7)
    b = chain(dask, 4, start, seed=7)
    assert len(dask.problems) >= 16 and dask.last_sweep["flips"] > 0
    assert all(np.array_equal(x, y) for x, y in zip(a, b, strict=True)), "a dask sweep differs from the threaded one"
    assert not np.array_equal(a[0], a[-1])
    assert dask.state_equals_scratch(), "the driver's kept sums drifted from the map"
    # a window is no larger than the 3 x 3 tiles around its tile (its rays stay in 2 x 2 tiles, but rays through
    # different cells reach different neighbours), plus the prior's reach, evened out
    T, e = dask.layout.T, dask.prior_extent
    assert max(max(p.rows, p.cols) for p in dask.problems) <= 3 * T + 2 * e + 2
    assert dask.last_sweep["bytes_sent"] == sum(-(-p.window_cells // 8) for p in dask.problems)
    dask.close()


def test_one_and_two_worker_processes_give_one_chain():
    model = scene(n=24, prior=MRFPrior((24, 24), order=1, psi=0.4, cell_prior=0.3))
    runs = []
    for workers in (1, 2):
        with DaskTileGibbs(model, scan="permutation", workers=workers) as k:
            assert len(k.client.scheduler_info()["workers"]) == workers
            torch.manual_seed(3)
            k.setup()
            runs.append(chain(k, 3, torch.from_numpy(k.state.astype(np.float64)), seed=4))
    assert all(np.array_equal(x, y) for x, y in zip(*runs, strict=True))


def test_a_task_alone_returns_the_tile_pass():
    """run_tile on one sub-problem (no cluster) equals the tile's updates in the threaded sweep."""
    model = scene(n=24, prior=pattern_field(24))
    k = ChromaticCellGibbs(model, tile=6, threads=1)
    k.setup()
    start = k.state.copy()
    problems = tile_problems(k)
    p = problems[0]
    window = p.window_of(24)
    values, flips = run_tile(p, np.packbits(start[window]), seed=123)
    from ogm_ppl.inference._kernels import cell_sweep as cs
    from ogm_ppl.inference._kernels import parallel as par

    st = cs.cell_state_of(start.copy(), k._index, k._bits)
    par.tile_pass(st, st.inf.view(np.int32), k._compiled, k.layout, p.t, np.uint64(123), 0, k._rule)
    assert np.array_equal(values, st.m[window[p.visit]])
    assert flips == int((values != start[window[p.visit]]).sum())


def test_long_runs_match_the_exact_marginals(client):
    """2 x 5 short-ray problem, tiles of one cell (several cells per phase), MRF prior: every marginal of a
    400-sweep chain within 5 batch-means standard errors (20 batches) of the brute-force one."""
    model = short_rays(prior=MRFPrior((2, 5), order=1, psi=0.4, cell_prior=0.4))
    k = DaskTileGibbs(model, tile=1, client=client)
    assert max(len(p.visit) for p in k.problems) == 1 and len(k.problems) == len(model.latent)
    assert_long_run_matches_brute_force(k, 400)


def test_pyro_mcmc_drives_it(client):
    from pyro.infer import MCMC

    model = scene(n=16, prior=MRFPrior((16, 16), order=1, psi=0.4, cell_prior=0.3))
    torch.manual_seed(0)
    mcmc = MCMC(DaskTileGibbs(model, client=client), num_samples=6, warmup_steps=2, disable_progbar=True)
    mcmc.run()
    assert mcmc.get_samples()["m"].shape == (6, len(model.latent))


# ---------------------------------------------------------------------------- limits
def test_long_cells_are_refused():
    model = scene(n=24)
    k = DaskTileGibbs(model, tile=2)
    with pytest.raises(ValueError, match="every cell short: use tile >= "):
        _ = k.problems


def test_table_priors_are_refused():
    prior = PatchTablePrior((24, 24), codes=[0, 0b0110, 0b1001], counts=[2, 1, 1], patch=(2, 2))
    with pytest.raises(TypeError, match="ChromaticCellGibbs or PatchGibbs"):
        _ = DaskTileGibbs(scene(n=24, prior=prior)).problems


def test_bad_arguments():
    model = scene(n=12)
    with pytest.raises(ValueError, match="workers must be a positive"):
        DaskTileGibbs(model, workers=0)
    with pytest.raises(ValueError, match="tiles_per_task must be a positive"):
        DaskTileGibbs(model, tiles_per_task=0)
    field = pattern_field(12).compiled()
    with pytest.raises(ValueError, match="even row and column"):
        window_prior(field, 12, 1, 0, 4, 4)
    with pytest.raises(NotImplementedError):
        DaskTileGibbs(model).run_marginals(3)
