"""Chromatic tile sweeps (:mod:`ogm_ppl.inference.mcmc.parallel`, :mod:`ogm_ppl.inference._kernels.parallel`):
the colouring rule, the threaded sweep equal to the serial composition of its updates (bit for bit, for any
thread count), the kept sums exact after concurrent writes, the kernel contract on enumerable problems
whose tiles are single cells, and long runs against the exact marginals."""

from __future__ import annotations

import math

import numba
import numpy as np
import pytest
import torch

from ogm_ppl import GaussianRange, Grid, OccupancyModel, Scans, raycast
from ogm_ppl.inference._kernels import cell_sweep as cs
from ogm_ppl.inference._kernels import parallel as par
from ogm_ppl.inference.exact import brute_force
from ogm_ppl.inference.mcmc import CellGibbs
from ogm_ppl.inference.mcmc.gibbs import _SCAN_CODES
from ogm_ppl.inference.mcmc.parallel import ChromaticCellGibbs
from ogm_ppl.priors import IndependentPrior, MRFPrior
from ogm_ppl.testing import KernelContract
from ogm_ppl.testing.kernels import _cell_matrix, _scan, enumerate_maps

THREADS = min(2, numba.config.NUMBA_NUM_THREADS)


def scene(n: int = 24, poses: int = 40, beams: int = 8, rmax: float = 5.0, seed: int = 0, prior=None):
    """An ``n x n`` grid seen from random poses with random readings of up to ``rmax`` cells."""
    g = np.random.default_rng(seed)
    grid = Grid((n, n), resolution=1.0)
    P = np.c_[g.uniform(1, n - 1, poses), g.uniform(1, n - 1, poses), g.uniform(-math.pi, math.pi, poses)]
    ang = np.linspace(-math.pi, math.pi, beams, endpoint=False)
    z = g.uniform(0.5, rmax, (poses, beams))
    scans = Scans(P, ang, z, max_range=rmax, over_range="max")
    prior = IndependentPrior(0.3, grid.num_cells) if prior is None else prior
    return OccupancyModel(grid, raycast(grid, scans), GaussianRange(1.0), prior)


def short_rays(shape=(2, 5), prior=None):
    """An enumerable grid whose rays each cross two cells (extent 1): with ``tile=1`` every tile is one
    cell and each colour phase updates several cells at once."""
    grid = Grid(shape, resolution=1.0)
    rows, cols = shape
    poses = [[0.5, 0.5, 0.0], [cols - 0.5, rows - 0.5, math.pi], [2.5, 0.5, math.pi / 2], [0.5, 0.5, math.pi / 2]]
    z = [[0.9], [0.6], [1.2], [0.3]]
    if rows > 2:
        poses += [[1.5, 2.5, 0.0], [3.5, 2.5, -math.pi / 2]]
        z += [[0.8], [1.1]]
    scans = Scans(np.array(poses), np.array([0.0]), np.array(z), max_range=1.2, over_range="max")
    prior = IndependentPrior(torch.linspace(0.25, 0.55, grid.num_cells)) if prior is None else prior
    return OccupancyModel(grid, raycast(grid, scans), GaussianRange(0.5), prior)


def sweep_seed(torch_seed: int) -> np.uint64:
    """The seed the kernel draws for its first sweep after ``torch.manual_seed(torch_seed)``."""
    torch.manual_seed(torch_seed)
    return np.uint64(int(torch.randint(0, 2**63 - 1, (), dtype=torch.int64)))


# ---------------------------------------------------------------------------- the tile layout
@pytest.mark.parametrize("T", [2, 5])
def test_tile_layout_groups_the_short_cells_by_tile_in_row_major_order(T):
    """The compiled grouping against the same layout built from numpy sorts, on an unsorted visit list."""
    model = scene(prior=MRFPrior((24, 24), order=2, psi=0.4, cell_prior=0.3))
    index = model.ray_index()
    cols = model.grid.cols
    visit = np.random.default_rng(T).permutation(model.latent.numpy())
    lay = par.tile_layout(visit, index.offsets, index.cells, index.c_off, 24, cols, T)
    sv = np.sort(visit)
    long = np.zeros(model.num_cells, bool)
    long[lay.long_cells] = True
    short = sv[~long[sv]]
    tile = (short // cols // T) * lay.n_tc + (short % cols) // T
    order = np.argsort(tile, kind="stable")
    counts = np.bincount(tile, minlength=lay.n_tr * lay.n_tc)
    assert np.array_equal(lay.tile_cells, short[order])
    assert np.array_equal(lay.tile_off, np.concatenate([[0], np.cumsum(counts)]))
    cost = np.bincount(tile, weights=np.diff(index.c_off)[short] + 1.0, minlength=len(counts))
    ids = np.nonzero(counts)[0]
    colour = par.colour_of_tile(ids, lay.n_tc)
    assert np.array_equal(lay.col_tiles, ids[np.lexsort((-cost[ids], colour))])  # largest first per colour
    assert np.array_equal(lay.long_cells, sv[long[sv]]) and (len(lay.long_cells) > 0) == (T == 2)


# ---------------------------------------------------------------------------- the colouring rule
@pytest.mark.parametrize("T", [2, 3, 4])
def test_no_short_ray_and_no_prior_pair_spans_two_tiles_of_one_colour(T):
    model = scene(prior=MRFPrior((24, 24), order=2, psi=0.4, cell_prior=0.3))
    index = model.ray_index()
    cols = model.grid.cols
    lay = par.tile_layout(model.latent.numpy(), index.offsets, index.cells, index.c_off, 24, cols, T)
    # every latent cell once, in a tile or among the long cells
    both = np.concatenate([lay.tile_cells, lay.long_cells])
    assert np.array_equal(np.sort(both), np.sort(model.latent.numpy()))
    r, c = np.divmod(np.arange(model.num_cells), cols)
    tile = (r // T) * lay.n_tc + c // T
    colour = par.colour_of_tile(tile, lay.n_tc)
    ext = par.ray_extents(index.offsets, index.cells, cols)
    is_long = np.zeros(model.num_cells, bool)
    is_long[lay.long_cells] = True
    confined = par.confined_rays(index.offsets, index.cells, cols, T, lay.n_tc)
    for ray in range(len(ext)):
        cells = index.cells[index.offsets[ray] : index.offsets[ray + 1]]
        spans = max(len(np.unique(tile[cells][colour[cells] == col])) for col in range(par.COLOURS))
        assert confined[ray] == (spans <= 1), ray
        assert confined[ray] or ext[ray] > T, f"ray {ray} of extent {ext[ray]} <= {T} spans two tiles of a colour"
        if not confined[ray]:
            assert is_long[np.intersect1d(cells, model.latent.numpy())].all()
    assert (~confined).any() and (confined & (ext > T)).any()  # long cells; longer rays that stay confined
    # the prior's pairs (8-connected: extent 1 <= T)
    assert par.prior_extent(model.prior.compiled()) == 1
    for dr in (-1, 0, 1):
        for dc in (-1, 0, 1):
            ok = (r + dr >= 0) & (r + dr < 24) & (c + dc >= 0) & (c + dc < cols)
            k, j = np.arange(model.num_cells)[ok], ((r + dr) * cols + c + dc)[ok]
            same_colour = colour[k] == colour[j]
            assert (tile[k][same_colour] == tile[j][same_colour]).all()


@pytest.mark.parametrize("T", [1, 3, 7])
def test_ray_runs_give_every_ray_cell_its_tile(T):
    """The runs of :func:`par.ray_runs` name the tile of each cell of each ray, and consecutive runs differ."""
    model = scene(n=20, rmax=9.0)
    idx = model.ray_index()
    cols = model.grid.shape[1]
    n_tc = -(-cols // T)
    seg_off, seg_start, seg_tile = par.ray_runs(idx.offsets, idx.cells, cols, T, n_tc)
    for r in range(len(idx.offsets) - 1):
        cells = idx.cells[idx.offsets[r] : idx.offsets[r + 1]]
        want = (cells // cols // T) * n_tc + (cells % cols) // T
        starts, tiles = seg_start[seg_off[r] : seg_off[r + 1]], seg_tile[seg_off[r] : seg_off[r + 1]]
        got = np.repeat(tiles, np.diff(np.r_[starts, len(cells)]))
        assert np.array_equal(got, want) and (len(cells) == 0 or starts[0] == 0)
        assert np.all(tiles[1:] != tiles[:-1])


def test_prior_extents():
    from ogm_ppl.priors import PatternFieldPrior
    from ogm_ppl.priors.pattern_field import symmetry_orbits

    assert par.prior_extent(IndependentPrior(0.3, 16).compiled()) == 0
    assert par.prior_extent(MRFPrior((4, 4), order=1).compiled()) == 1
    assert par.prior_extent(MRFPrior((4, 4), order=2).compiled()) == 1
    n = symmetry_orbits(3)[1]
    assert par.prior_extent(PatternFieldPrior((8, 8), np.zeros(n), 3).compiled()) == 2
    assert par.prior_extent(PatternFieldPrior((8, 8), np.zeros(n), 3, np.zeros(n)).compiled()) == 5
    field = scene(n=8, prior=PatternFieldPrior((8, 8), np.zeros(n), 3))
    with pytest.raises(ValueError, match="smaller than the prior"):
        _ = ChromaticCellGibbs(field, tile=1).layout
    with pytest.raises(ValueError, match="positive"):
        ChromaticCellGibbs(short_rays(), tile=0)


def test_default_tile_makes_every_cell_short():
    k = ChromaticCellGibbs(scene(n=24))
    assert k.layout.T == max(k.ray_extent, 1) and len(k.layout.long_cells) == 0


def groups(lay):
    """``(stream, cells)`` of each update group of a sweep, in order."""
    tiles = [(int(t), lay.tile_cells[lay.tile_off[t] : lay.tile_off[t + 1]]) for t in lay.col_tiles]
    return tiles + [(lay.n_tiles, lay.long_cells)]


# ---------------------------------------------------------------------------- threads: exact and reproducible
@pytest.mark.parametrize(
    "scan, update, mrf",
    [("systematic", "gibbs", False), ("permutation", "metropolised", True), ("random", "gibbs", True)],
)
def test_threaded_sweep_is_the_serial_composition_for_any_thread_count(scan, update, mrf):
    prior = MRFPrior((24, 24), order=1, psi=0.4, cell_prior=0.3) if mrf else None
    model = scene(prior=prior)
    runs = []
    for threads in sorted({1, THREADS}):
        torch.manual_seed(11)
        k = ChromaticCellGibbs(model, scan=scan, update=update, tile=4, threads=threads)
        k.setup()
        lay = k.layout
        assert len(lay.long_cells) > 0 and np.diff(lay.col_off).min() >= 4  # both phases are exercised
        start = k.state.copy()
        # the reference: the same updates one after another, on a state of its own
        ref = cs.cell_state_of(start.copy(), k._index, k._bits)
        seed = sweep_seed(5)
        for t, cells in groups(lay):
            order, u = cs.draws(cells, _SCAN_CODES[scan], np.uint64(par.tile_seed(seed, t)))
            cs.sweep(ref, order, k._compiled, u, k._rule)
        torch.manual_seed(5)
        p = k.sample(k.current_params())
        assert np.array_equal(k.state, ref.m), "one threaded sweep differs from its serial composition"
        assert not np.array_equal(k.state, start)
        for _ in range(8):
            p = k.sample(p)
        assert k.state_equals_scratch(), "the kept sums lost a concurrent write"
        runs.append(k.state.copy())
    assert all(np.array_equal(runs[0], x) for x in runs)


def test_infinite_terms_are_counted_exactly_under_threads():
    """Impossible readings (3 % of the table's entries ``-inf``): the counts of infinite terms, written
    across tiles as int32 atomics, stay those of the serial composition and of a fresh state."""
    model = scene(seed=3)
    rng = np.random.default_rng(4)
    idx = model.ray_index()
    ll = idx.ll.copy()
    ll[rng.random(ll.shape) < 0.03] = -np.inf
    idx = idx._replace(ll=ll)
    lay = par.tile_layout(model.latent.numpy(), idx.offsets, idx.cells, idx.c_off, 24, 24, 3)
    m0 = (rng.random(model.num_cells) < 0.25).astype(np.uint8)
    m0[model.known_free.numpy()] = 0
    st, ref = cs.cell_state_of(m0.copy(), idx), cs.cell_state_of(m0.copy(), idx)
    assert st.any_inf and (st.inf["pos"] > 0).any() and (st.inf["neg"] > 0).any()
    prior = model.prior.compiled()
    numba.set_num_threads(THREADS)
    flips = 0
    for sweep in range(4):
        seed = np.uint64(1000 + sweep)
        flips += par.chromatic_sweep(
            st, st.inf.view(np.int32), prior, lay, seed, cs.PERMUTATION, cs.METROPOLISED, numba.get_num_threads()
        )
        for t, cells in groups(lay):
            order, u = cs.draws(cells, cs.PERMUTATION, np.uint64(par.tile_seed(seed, t)))
            cs.sweep(ref, order, prior, u, cs.METROPOLISED)
        for name in ("m", "rays", "d", "inf"):
            assert np.array_equal(getattr(st, name), getattr(ref, name)), (sweep, name)
    fresh = cs.cell_state_of(st.m.copy(), idx)
    assert np.array_equal(fresh.d, st.d) and np.array_equal(fresh.inf, st.inf) and np.array_equal(fresh.rays, st.rays)
    assert flips > 0


# ---------------------------------------------------------------------------- the kernel contract
class _ChromaticContract(KernelContract):
    """The contract with the exact sweep matrix of the chromatic order: the groups (tiles colour by
    colour, then the long cells) one after another, each scanned as the kernel's ``scan`` says."""

    scan = "systematic"
    update = "gibbs"
    #: the chain does not depend on the thread count (tested above with 1 and 2 threads, bit for bit); one
    #: thread keeps the 2000-odd one-sweep chains of the contract fast where the cores are shared (each
    #: parallel region then waits for a core)
    threads = 1

    def make_kernel(self, model, region=None):
        return ChromaticCellGibbs(
            model, scan=self.scan, update=self.update, region=region, tile=1, threads=self.threads
        )

    def problem_2d(self):
        return short_rays()

    def transition_matrix(self, kernel, rows=None):
        rows = torch.arange(2 ** len(kernel.model.latent)) if rows is None else rows
        P = torch.eye(2 ** len(kernel.model.latent), dtype=torch.float64)
        for cells in kernel.tile_cells():
            mats = [_cell_matrix(kernel, int(k), kernel.update, rows) for k in cells]
            if mats:
                G = _scan(mats, kernel.scan)
                if G is None:
                    return None
                P = P @ G
        return P

    def test_short_cells_share_a_phase(self):
        k = self.make_kernel(self.problem_2d())
        lay = k.layout
        assert len(lay.tile_cells) >= 4 and np.diff(lay.col_off).max() >= 2


class TestChromaticSystematic(_ChromaticContract):
    pass


class TestChromaticPermutationMetropolised(_ChromaticContract):
    scan = "permutation"
    update = "metropolised"


class TestChromaticRandomMRF(_ChromaticContract):
    scan = "random"

    def problem_2d(self):
        return short_rays(prior=MRFPrior((2, 5), order=1, psi=0.4, cell_prior=0.4))


# ---------------------------------------------------------------------------- long runs
def test_long_runs_match_the_exact_marginals_as_the_serial_chain_does():
    """3 x 4 short-ray problem (tiles of one cell, MRF prior): chromatic and serial chains of ``n`` sweeps;
    each marginal within 5 batch-means standard errors (20 batches) of the exact one. The chromatic chain
    runs on one thread: with more it is the same chain bit for bit (the tests above), and on shared cores
    each of its parallel regions would wait for a core."""
    model = short_rays((3, 4), prior=MRFPrior((3, 4), order=1, psi=0.4, cell_prior=0.4))
    for kernel in (ChromaticCellGibbs(model, tile=1, threads=1), CellGibbs(model)):
        assert_long_run_matches_brute_force(kernel, 3000)


def assert_long_run_matches_brute_force(kernel, n: int, batches: int = 20) -> None:
    """Run ``kernel`` (seed 0) for ``n`` sweeps on its enumerable model: every marginal within 5 batch-means
    standard errors (``batches`` batches) of the brute-force one, plus 1e-3 for cells that barely move."""
    model = kernel.model
    pi = brute_force(model).log_probs.exp()
    exact = ((pi[:, None] * enumerate_maps(model)).sum(0)[model.latent]).numpy()
    torch.manual_seed(0)
    kernel.setup()
    p = kernel.current_params()
    trace = np.empty((n, len(model.latent)))
    for i in range(n):
        p = kernel.sample(p)
        trace[i] = p["m"].numpy()
    means = trace.reshape(batches, -1, trace.shape[1]).mean(1)
    se = means.std(0, ddof=1) / math.sqrt(batches)
    err = np.abs(trace.mean(0) - exact)
    assert (err <= 5 * se + 1e-3).all(), f"{type(kernel).__name__}: errors {err} vs se {se}"


def test_take_tile_hands_out_each_tile_once_to_concurrent_threads():
    """par.take_tile under numba's threads: every thread takes tiles from one shared counter until none is
    left; each of the n tiles is taken exactly once (the atomic fetch-and-add loses no increment)."""

    @numba.njit(parallel=True)
    def take_all(n, P, reps):
        hits = np.zeros(n, np.int64)
        for _ in range(reps):
            taken = np.zeros(1, np.int64)
            for _p in numba.prange(P):
                j = par.take_tile(taken, n)
                while j < n:
                    par.atomic_add(hits, j, np.int64(1))
                    j = par.take_tile(taken, n)
        return hits

    for n in (0, 1, 9, 1000):
        hits = take_all(n, THREADS, 50)
        assert hits.shape == (n,) and (hits == 50).all()
