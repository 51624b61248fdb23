import numpy as np
import pytest
import torch

from ogm_ppl import GaussianRange, Grid, OccupancyModel, PatternMatch, Scans, raycast
from ogm_ppl.inference._kernels.cells import first_hits
from ogm_ppl.priors import IndependentPrior


def test_first_hits_agree_with_compiled_kernel_and_a_loop():
    rng = np.random.default_rng(0)
    grid = Grid((12, 15), resolution=1.0)
    scans = Scans(
        np.c_[rng.uniform(0, 15, 4), rng.uniform(0, 12, 4), rng.uniform(-3, 3, 4)],
        rng.uniform(-3, 3, 30),
        rng.uniform(0, 9, (4, 30)),
        max_range=8.0,
        over_range="max",
    )
    rays = raycast(grid, scans)
    model = OccupancyModel(grid, rays, GaussianRange(1.0), IndependentPrior(0.3, grid.num_cells))
    maps = (torch.rand(5, grid.num_cells, generator=torch.Generator().manual_seed(1)) < 0.2).double()
    got = model.first_hits(maps)
    for b in range(5):
        m = maps[b].numpy().astype(np.uint8)
        np.testing.assert_array_equal(got[b].numpy(), first_hits(m, rays.offsets, rays.cells))
        for r in range(rays.num_rays):
            occ = [k for k, c in enumerate(rays.ray(r)) if m[c]]
            assert got[b, r] == (occ[0] if occ else rays.lengths[r])


def _cut_ray_model(K, readings, lam, sigma=1.0, max_range=20.0, sensor=None):
    grid = Grid.line(K)
    rays = raycast(grid, Scans.one_d(readings, max_range=max_range))
    return OccupancyModel(grid, rays, sensor or GaussianRange(sigma), IndependentPrior(lam, K))


def test_ray_cut_by_grid_edge_is_a_normalised_distribution_over_readings():
    # a 9-cell grid and a sensor that reaches 20 cells: every outcome (a hit at kappa 0..20, max range)
    # summed for every map of the grid must give 1 (it would give 1.40 if the edge censored max range
    # and a hit past the edge counted as an obstacle at the reading)
    # The pattern-matching sensor has discrete outcomes: exact to rounding. The Gaussian is a density
    # on continuous ranges, so its sum over integer kappa is a Riemann sum: exact to ~1e-3 only.
    # near-face ranges of kappa 0..20 (continuous kappa r + 1/2 = 1..20 on the integer lattice), max range
    readings = [0.0] + [z - 0.5 for z in range(1, 21)] + [20.0]
    for lam in (0.5, 0.234, 0.05):
        for sensor, cols, tol in ((PatternMatch(0.8), range(10), 1e-12), (GaussianRange(1.0), range(4, 10), 1e-3)):
            model = _cut_ray_model(9, readings, lam, sensor=sensor)
            rays = model.rays
            assert (rays.lengths == 9).all() and (rays.range_len == 21).all()
            assert rays.z[:21].tolist() == list(range(21)) and rays.is_max.tolist() == [False] * 21 + [True]
            table = model.loglik_table
            # every first hit f in the grid and none in the grid (column 9); for the Gaussian, f >= 4
            # (its mass below kappa -1/2 is < 1e-5)
            for col in cols:
                total = torch.logsumexp(table[:, col], 0).exp().item()
                assert total == pytest.approx(1.0, abs=tol), (sensor, lam, col, total)


def test_cells_beyond_the_edge_are_marginalised_under_the_prior():
    # the cut model equals a model of the whole ray (21 cells) with the 12 outside cells summed out
    # under the independent prior, for hits in the grid, past the edge and max range
    lam = 0.3
    readings = [3.0, 6.0, 11.0, 17.0, 20.0]
    small = _cut_ray_model(9, readings, lam, sigma=2.0)
    big = _cut_ray_model(21, readings, lam, sigma=2.0)
    assert (big.rays.lengths == 21).all()
    outside = torch.tensor(list(__import__("itertools").product([0.0, 1.0], repeat=12)), dtype=torch.float64)
    log_p_out = IndependentPrior(lam, 12).log_prob(outside)
    for inside in ([0] * 9, [0, 0, 0, 0, 0, 1, 0, 0, 0], [0, 0, 0, 0, 0, 0, 0, 0, 1]):
        m_in = torch.tensor(inside, dtype=torch.float64)
        full = torch.cat([m_in.expand(len(outside), -1), outside], 1)
        f_big = big.first_hits(full)  # 4096 x R
        per_ray = big.loglik_table[torch.arange(len(readings))[None, :], f_big]  # 4096 x R
        expected = torch.logsumexp(per_ray + log_p_out[:, None], 0)
        got = small.loglik_table[torch.arange(len(readings)), small.first_hits(m_in)]
        torch.testing.assert_close(got, expected, rtol=0, atol=1e-10)


def test_likelihood_of_in_grid_hits():
    grid = Grid.line(6)
    scans = Scans.one_d([2.0, 9.0, 20.0], max_range=20.0)  # in grid, past the edge, max range
    rays = raycast(grid, scans)
    assert rays.endpoint_in_grid.tolist() == [True, False, False] and rays.is_max.tolist() == [False, False, True]
    s = GaussianRange(1.5)
    model = OccupancyModel(grid, rays, s, IndependentPrior(0.5, 6))
    wall = torch.zeros(6)
    wall[4] = 1.0
    # the sensor's ray reaches kappa 20 whatever the grid holds: max range is censored there
    # GaussianRange is evaluated on the range in continuous kappa r + 1/2; the wall cell 4 is entered
    # at 3.5 cells (kappa_c 4)
    expected = (
        s.log_prob(torch.tensor(2.5), 4, 20)
        + s.log_prob(torch.tensor(9.5), 4, 20)
        + s.log_prob(torch.tensor(0.0), 4, 20, is_max=True)
    )
    assert model.log_likelihood(wall).item() == pytest.approx(expected.item(), abs=1e-12)
    assert model.known_free.tolist() == [True] + [False] * 5


def test_model_validation():
    grid = Grid.line(6)
    rays = raycast(grid, Scans.one_d([2.0], max_range=5.0))
    with pytest.raises(ValueError, match="prior has 4 cells"):
        OccupancyModel(grid, rays, GaussianRange(1.0), IndependentPrior(0.5, 4))
    with pytest.raises(ValueError, match="different grid"):
        OccupancyModel(Grid.line(7), rays, GaussianRange(1.0), IndependentPrior(0.5, 7))
    with pytest.raises(ValueError, match="known_free"):
        OccupancyModel(grid, rays, GaussianRange(1.0), IndependentPrior(0.5, 6), known_free=[9])
    m = OccupancyModel(grid, rays, GaussianRange(1.0), IndependentPrior(0.5, 6), known_free=None)
    assert len(m.latent) == 6
    with pytest.raises(TypeError, match="sensor must be a SensorModel"):
        OccupancyModel(grid, rays, "gaussian", IndependentPrior(0.5, 6))
    with pytest.raises(TypeError, match="prior must be a MapPrior"):
        OccupancyModel(grid, rays, GaussianRange(1.0), 0.3)


def test_a_prior_laid_out_on_another_shape_is_refused():
    """A spatial prior of the grid's cell count but another layout (a 1D chain of 16 cells, 2 x 8, 8 x 2 on a
    4 x 4 grid; 3 x 4 on a line of 12) gives another posterior without a word: refused, wrapped or not."""
    from ogm_ppl.priors import MRFPrior, TemperedPrior, prior_by_name

    grid = Grid((4, 4), 1.0)
    rays = raycast(grid, Scans(torch.tensor([[1.5, 1.5, 0.0]]), torch.tensor([[0.0]]), torch.tensor([[2.0]]), 3.0))
    for prior in (MRFPrior((16,)), MRFPrior((2, 8)), prior_by_name("patch3_bo", (8, 2))):
        with pytest.raises(ValueError, match=r"laid out on .* cells, the grid on 4 x 4"):
            OccupancyModel(grid, rays, GaussianRange(1.0), prior)
    with pytest.raises(ValueError, match="laid out on 1 x 16 cells"):
        OccupancyModel(grid, rays, GaussianRange(1.0), TemperedPrior(MRFPrior((16,)), 0.5))
    OccupancyModel(grid, rays, GaussianRange(1.0), MRFPrior((4, 4)))
    line = Grid.line(12)
    with pytest.raises(ValueError, match="laid out on 3 x 4 cells, the grid on 1 x 12"):
        OccupancyModel(line, raycast(line, Scans.one_d([2.0], max_range=5.0)), GaussianRange(1.0), MRFPrior((3, 4)))


@pytest.mark.parametrize("sensor", [GaussianRange(1.5, 1e-3), PatternMatch(0.8)])
def test_likelihood_table_built_in_blocks_equals_one_block(monkeypatch, sensor):
    """The table is built in blocks of rays (bounded memory on 2 cm Intel); any block size gives the same
    table (to the last bits torch's vector and scalar loops may round apart), cut rays and max-range readings
    included."""
    import ogm_ppl.models.occupancy as occ

    grid = Grid((30, 40), resolution=0.1, origin=(0.0, 0.0))
    rng = np.random.default_rng(3)
    angles = np.linspace(-np.pi, np.pi, 45, endpoint=False)
    ranges = rng.uniform(0.2, 2.9, size=(3, 45))
    ranges[:, ::7] = 3.0  # max range
    scans = Scans(
        poses=[[1.0, 1.5, 0.0], [2.0, 1.0, 1.0], [3.5, 2.5, -2.0]], angles=angles, ranges=ranges, max_range=3.0
    )
    rays = raycast(grid, scans)
    assert (rays.range_len > rays.lengths).any()  # some rays leave the grid
    whole = OccupancyModel(grid, rays, sensor, IndependentPrior(0.3, grid.num_cells)).loglik_table
    monkeypatch.setattr(occ, "_TABLE_BLOCK", 7 * int(rays.lengths.max()))  # 7 rays a block, many blocks
    blocked = OccupancyModel(grid, rays, sensor, IndependentPrior(0.3, grid.num_cells)).loglik_table
    assert torch.equal(torch.isinf(whole), torch.isinf(blocked))
    fin = torch.isfinite(whole)
    # each entry is the same formula of the same numbers, but torch runs an elementwise op on a tensor's SIMD
    # vectors and on its tail in scalar code, which may round exp and log1p (inside logaddexp, p_rand > 0) one
    # ulp apart; which entries fall in a tail depends on the block's size and the CPU's vector width. The
    # log1p term lies in [0, log 2], so an entry moves by at most 2 eps64 there and 1 ulp in the final addition
    w, b = whole[fin].numpy(), blocked[fin].numpy()
    assert (np.abs(w - b) <= 2 * np.spacing(np.abs(w)) + 2 * np.finfo(np.float64).eps).all()


def test_several_rays_marginalise_the_outside_cells_each_on_their_own():
    # the documented condition of the cut-ray model (docs/guide/model.md): four readings along one line
    # through a 9-cell grid (range 12) each sum the 4 outside cells out on their own; a 13-cell grid holding
    # those cells shares them. For one ray the two agree (test above); for four they differ.
    from ogm_ppl.inference import exact

    def model(K):
        rays = raycast(Grid.line(K), Scans.one_d([7.2, 9.5, 9.8, 10.1], max_range=12.0))
        return OccupancyModel(Grid.line(K), rays, GaussianRange(1.0), IndependentPrior(0.5, K))

    per_ray = exact.brute_force(model(9)).marginals
    shared = exact.brute_force(model(13)).marginals[:9]
    assert per_ray[8].item() == pytest.approx(0.00758, abs=5e-5)
    assert shared[8].item() == pytest.approx(0.01033, abs=5e-5)
    one = [
        exact.brute_force(
            OccupancyModel(
                Grid.line(K),
                raycast(Grid.line(K), Scans.one_d([9.5], max_range=12.0)),
                GaussianRange(1.0),
                IndependentPrior(0.5, K),
            )
        ).marginals[:9]
        for K in (9, 13)
    ]
    torch.testing.assert_close(one[0], one[1], rtol=0, atol=1e-12)


def test_a_model_too_big_for_free_memory_is_refused_before_it_is_built(monkeypatch):
    """A map too fine or a log too long for the machine fails at once with the numbers, not by swapping."""
    import ogm_ppl.models.occupancy as occ

    grid = Grid.line(6)
    rays = raycast(grid, Scans.one_d([2.0, 4.0], max_range=5.0))
    monkeypatch.setattr(occ, "available_memory", lambda: 100)
    with pytest.raises(MemoryError, match=r"rays cross \d+ cells .* more than the 0\.0 GiB this machine has free"):
        OccupancyModel(grid, rays, GaussianRange(1.0), IndependentPrior(0.5, 6))
    monkeypatch.setattr(occ, "available_memory", lambda: None)  # unknown: not checked
    OccupancyModel(grid, rays, GaussianRange(1.0), IndependentPrior(0.5, 6))


def test_memory_needed_counts_crossings_and_the_tables_working_blocks(monkeypatch):
    """The guard's estimate: 64 bytes a crossing plus the likelihood table's working blocks, at most
    ``_TABLE_BLOCK`` entries a block (``benchmarks/bench_memory.py`` measures the peak against it)."""
    import ogm_ppl.models.occupancy as occ

    rays = raycast(Grid.line(6), Scans.one_d([2.0, 4.0], max_range=5.0))
    R, W = rays.num_rays, int(rays.lengths.max()) + 1
    per_crossing = rays.cells.size * occ.BYTES_PER_CROSSING
    assert occ.memory_needed(rays) == per_crossing + occ.TABLE_TEMPORARIES * 8 * R * W
    monkeypatch.setattr(occ, "_TABLE_BLOCK", 2)  # a table of more entries than a block: one block's worth
    assert occ.memory_needed(rays) == per_crossing + occ.TABLE_TEMPORARIES * 8 * 2
