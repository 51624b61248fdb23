"""OnlineMap: scans added to a running chain equal a rebuild (bit for bit on the kept state), the focused
and full sweeps leave the exact posterior given all scans stationary, and bad input is refused."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from ogm_ppl import GaussianRange, Grid, OccupancyModel, Scans, raycast
from ogm_ppl.datasets import simulate_scans
from ogm_ppl.inference._kernels import cell_sweep as cs
from ogm_ppl.inference._kernels import online as ok
from ogm_ppl.inference.exact import brute_force
from ogm_ppl.inference.online import OnlineMap, TilePriorWarning
from ogm_ppl.priors import IndependentPrior, MRFPrior, PatternFieldPrior, prior_by_name
from ogm_ppl.testing.kernels import _cell_matrix, enumerate_maps

N = 16


def _prior(name: str, shape):
    K = int(np.prod(shape))
    if name == "independent":
        return IndependentPrior(torch.linspace(0.25, 0.55, K))
    if name == "mrf":
        return MRFPrior(shape, order=1, psi=0.4, cell_prior=0.35)
    rng = np.random.default_rng(3)
    return PatternFieldPrior(shape, rng.normal(0.0, 0.5, 16), w=2, occupancy=0.3)


def _scene(num_scans: int = 6, seed: int = 5):
    rng = np.random.default_rng(seed)
    truth = np.zeros((N, N), bool)
    truth[0, :] = truth[-1, :] = truth[:, 0] = truth[:, -1] = True
    truth[6, 3:11] = truth[4:14, 12] = True
    grid = Grid((N, N), resolution=0.1)
    free = np.argwhere(~truth)
    pick = free[rng.choice(len(free), num_scans, replace=False)]
    poses = np.c_[(pick[:, 1] + 0.5) * 0.1, (pick[:, 0] + 0.5) * 0.1, rng.uniform(-np.pi, np.pi, num_scans)]
    scans = simulate_scans(grid, truth, poses, np.arange(40) * (2 * np.pi / 40), 1.2, 1.0, 3)
    return grid, scans


def _with_first_twice(scans: Scans) -> Scans:
    """The scans with the first one repeated after it (its sensor cell then holds twice the rays)."""
    i = np.r_[0, np.arange(scans.num_scans)]
    return Scans(scans.poses[i], scans.angles[i], scans.ranges[i], scans.max_range, valid=scans.valid[i])


def _part(scans: Scans, a: int, b: int) -> Scans:
    return Scans(scans.poses[a:b], scans.angles[a:b], scans.ranges[a:b], scans.max_range, valid=scans.valid[a:b])


def _assert_same_as_rebuilt(om: OnlineMap, grid, scans, sensor, prior) -> None:
    """The online kept state equals the from-scratch state of the same map on all scans (same S): the fixed-point
    sums up to the rebuilt table's last-bit differences, and exactly on the kept table itself."""
    model = OccupancyModel(grid, raycast(grid, scans), sensor, prior)
    st = cs.cell_state_of(om.state.numpy(), model.ray_index(), om.bits)
    ks = om.kept_state()
    assert np.array_equal(om.pinned.numpy(), model.known_free.numpy())
    assert np.array_equal(ks["f"], st.rays["f"]) and np.array_equal(ks["s"], st.rays["s"])
    assert np.array_equal(ks["inf_pos"], st.inf["pos"]) and np.array_equal(ks["inf_neg"], st.inf["neg"])
    # the rows of the new rays come from the offline code on the new rays alone: torch's vectorised and
    # scalar loops may round the last bit differently (which entries, depends on the tensors' sizes and the
    # CPU's vector width), so the table agrees to 2 ulp
    lengths = model.rays.lengths
    rows = np.repeat(np.arange(len(lengths)), lengths + 1)
    cols = np.arange(int((lengths + 1).sum())) - np.repeat(np.cumsum(lengths + 1) - lengths - 1, lengths + 1)
    offline = model.loglik_table.numpy()[rows, cols]
    assert np.array_equal(np.isfinite(ks["ll"]), np.isfinite(offline))
    fin = np.isfinite(offline)
    assert (np.abs(ks["ll"][fin] - offline[fin]) <= 2 * np.spacing(np.abs(offline[fin]))).all()
    assert om._st.any_inf == st.any_inf
    # so the fixed-point sums over the rebuilt table may differ: an entry 2 ulp off moves rint(x 2^S) by up to
    # 2 ulp 2^S + 1 units, and each crossing of a cell adds a difference of two entries
    one_term = 2 * np.spacing(np.abs(offline[fin])).max() * 2.0**om.bits + 1
    crossings = np.diff(model.ray_index().c_off)
    assert (np.abs(ks["d"] - st.d) <= crossings * 2 * one_term).all()
    # and exactly the state a rebuild gives on the online table itself
    own = np.full_like(model.loglik_table.numpy(), -np.inf)
    own[rows, cols] = ks["ll"]
    idx = model.ray_index()
    st2 = cs.cell_state(om.state.numpy(), idx.offsets, idx.cells, idx.c_off, idx.c_ray, idx.c_kappa, own, om.bits)
    assert np.array_equal(ks["d"], st2.d) and np.array_equal(ks["f"], st2.rays["f"])
    assert np.array_equal(ks["inf_pos"], st2.inf["pos"]) and np.array_equal(ks["inf_neg"], st2.inf["neg"])


@pytest.mark.parametrize("prior_name", ["independent", "mrf", "pattern"])
@pytest.mark.parametrize("p_rand", [0.0, 0.05])
def test_add_scans_equals_rebuild_bit_for_bit(prior_name, p_rand):
    grid, scans = _scene()
    scans = _with_first_twice(scans)
    sensor, prior = GaussianRange(1.0, p_rand), _prior(prior_name, (N, N))
    # a small cap on the rays a cell holds: the repeated first scan doubles it, so the fixed-point scale is
    # lowered and the sums refilled on the way
    om = OnlineMap(grid, sensor, prior, seed=3, sweeps_per_scan=3, full_every=4, initial_rays_per_cell=1)
    for a, b in [(0, 1), (1, 2), (2, 4), (4, 5), (5, 7)]:
        om.add_scans(_part(scans, a, b))
        _assert_same_as_rebuilt(om, grid, _part(scans, 0, b), sensor, prior)
    assert om.rescales > 0 and om.full_sweeps > 0 and om.state.sum() > 0
    # and from the same state, the same uniforms move both chains alike
    model = om.model
    st = cs.cell_state_of(om.state.numpy(), model.ray_index(), om.bits)
    cells = model.latent.numpy().astype(np.int64)
    rng = np.random.default_rng(0)
    for _ in range(3):
        u = rng.random(len(cells))
        a = cs.sweep(st, cells, prior.compiled(), u, cs.HEAT_BATH)
        b = ok.sweep(om._st, cells, prior.compiled(), u, cs.HEAT_BATH)
        assert a == b and np.array_equal(st.m, om._st.m)
    _assert_same_as_rebuilt(om, grid, scans, sensor, prior)


def test_growth_keeps_memory_bounded():
    grid, scans = _scene(num_scans=12, seed=8)
    om = OnlineMap(grid, GaussianRange(1.0), _prior("independent", (N, N)), sweeps_per_scan=0)
    for i in range(12):
        om.add_scans(_part(scans, i, i + 1))
        s = om.stats()
        assert s.ray_capacity <= max(2 * s.rays, 16) and s.entry_capacity <= max(2 * s.nnz, 16)
        assert s.pool_capacity <= max(2 * (2 * s.nnz + ok.MIN_BLOCK * grid.num_cells), 1024)
    assert om.num_scans == 12 and om.num_rays == om.model.rays.num_rays


def _enumerable_scans():
    return Scans(
        [[0.5, 0.5, 0.0], [0.5, 0.5, 0.0], [3.5, 1.5, math.pi], [0.5, 0.5, math.pi / 2]],
        [0.0],
        [[2.2], [3.9], [1.4], [1.0]],
        max_range=3.9,
        over_range="max",
    )


@pytest.mark.parametrize("prior_name", ["independent", "mrf", "pattern"])
def test_focused_and_full_sweeps_leave_the_posterior_given_all_scans_stationary(prior_name):
    grid, scans = Grid((2, 4), resolution=1.0), _enumerable_scans()
    prior = _prior(prior_name, (2, 4))
    om = OnlineMap(grid, GaussianRange(0.9), prior, seed=2, margin=0, full_every=3)
    om.add_scans(_part(scans, 0, 2), sweeps=4)
    om.add_scans(_part(scans, 2, 4), sweeps=2)
    model = om.model
    pi = brute_force(model).log_probs.exp()
    rows = torch.arange(len(pi))
    latent = model.latent.numpy()
    assert 0 < len(om.focus) < len(latent)  # a strict subset: the focused sweep is not the full one
    for cells in (om.focus, latent):
        P = torch.eye(len(pi), dtype=torch.float64)
        for k in cells:
            P = P @ _cell_matrix(om, int(k), "gibbs", rows)
        assert torch.allclose(P.sum(1), torch.ones(len(pi), dtype=torch.float64), atol=1e-12)
        assert (pi @ P - pi).abs().max() < 1e-12
        assert (P.diagonal() < 1 - 1e-9).any()  # it moves


def test_long_online_run_matches_the_exact_marginals():
    grid, scans = Grid((2, 4), resolution=1.0), _enumerable_scans()
    prior = _prior("mrf", (2, 4))
    om = OnlineMap(grid, GaussianRange(0.9), prior, seed=7, margin=0, full_every=3)
    om.add_scans(_part(scans, 0, 3), sweeps=5)
    om.add_scans(_part(scans, 3, 4), sweeps=50)  # burn-in
    om.reset_marginals()
    n, batches = 30000, 30
    draws = om.samples(n, focus=True).double()
    exact = brute_force(om.model).marginals
    assert torch.allclose(om.marginals, draws.mean(0), atol=1e-12)
    means = draws.reshape(batches, n // batches, -1).mean(1)
    # batch means (the autocorrelation stays inside each batch), at least the independent-draws error
    se = torch.maximum(means.std(0) / math.sqrt(batches), (exact * (1 - exact) / n).sqrt())
    err = (draws.mean(0) - exact).abs()
    assert (err <= 5 * se + 1e-9).all(), (err, se)


def test_bad_input_is_refused():
    grid, scans = _scene(num_scans=2)
    sensor = GaussianRange(1.0)
    om = OnlineMap(grid, sensor, _prior("independent", (N, N)))
    with pytest.raises(ValueError, match="another sensor model"):
        om.add_scans(_part(scans, 0, 1), sensor=GaussianRange(2.0))
    with pytest.raises(ValueError, match="another grid"):
        om.add_scans(_part(scans, 0, 1), grid=Grid((N, N + 1), resolution=0.1))
    empty = Scans(scans.poses[:1], scans.angles[:1], scans.ranges[:1], scans.max_range, valid=np.zeros((1, 40), bool))
    with pytest.raises(ValueError, match="no reading"):
        om.add_scans(empty)
    off = Scans([[5.0, 5.0, 0.0]], [0.0], [[0.5]], max_range=1.2)
    with pytest.raises(ValueError, match="outside the grid"):
        om.add_scans(off)
    om.add_scans(_part(scans, 0, 1), sensor=GaussianRange(1.0), grid=grid)
    other = Scans(scans.poses[1:2], scans.angles[1:2], np.minimum(scans.ranges[1:2], 1.0), 1.0, valid=scans.valid[1:2])
    with pytest.raises(ValueError, match="maximum range"):
        om.add_scans(other)
    with pytest.raises(TypeError, match="Scans"):
        om.add_scans(np.zeros(3))  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="compiled face"):

        class Plain(IndependentPrior):
            def compiled(self):
                return None

        OnlineMap(grid, sensor, Plain(0.3, grid.num_cells))
    with pytest.raises(ValueError, match="kernel"):
        OnlineMap(grid, sensor, _prior("independent", (N, N)), kernel="patch")
    # a prior of another shape with as many cells (transposed), a shape for a grid, a tile table
    wide = Grid((6, 24), resolution=0.1)
    with pytest.raises(ValueError, match="laid out on 24 x 6 cells, the grid on 6 x 24"):
        OnlineMap(wide, sensor, prior_by_name("mrf8:houseexpo@cal", (24, 6)))
    with pytest.raises(TypeError, match=r"grid must be an ogm_ppl\.Grid"):
        OnlineMap(grid.shape, sensor, _prior("independent", (N, N)))  # type: ignore[arg-type]
    with pytest.warns(TilePriorWarning, match="RebuildMapper"):
        OnlineMap(grid, sensor, prior_by_name("patch3_bo:houseexpo", grid.shape))
    assert om.num_scans == 1  # the refused scans left the map as it was
    with pytest.raises(ValueError, match="pinned"):
        m = np.zeros(grid.num_cells)
        m[np.flatnonzero(om.pinned.numpy())[0]] = 1
        om.set_state(m)


def test_enumerate_maps_order_matches_online_state():
    grid, scans = Grid((2, 4), resolution=1.0), _enumerable_scans()
    om = OnlineMap(grid, GaussianRange(0.9), _prior("independent", (2, 4)), sweeps_per_scan=0)
    om.add_scans(scans)
    maps = enumerate_maps(om.model)
    om.set_state(maps[5])
    assert torch.equal(om.state.double(), maps[5])


def test_cli_map_online_with_snapshots(tmp_path):
    from ogm_ppl.cli import load_map, main
    from tests.test_cli import POSES, write_log

    log = write_log(tmp_path / "tiny.log")
    out = tmp_path / "out"
    argv = ["map", str(log), "--resolution", "0.1", "--method", "gibbs", "--sweeps", "5", "--out", str(out)]
    assert main([*argv, "--online", "--snapshots", "2"]) == 0
    m = load_map(out / "map.npz")
    report = __import__("json").loads((out / "report.json").read_text())
    assert report["method"]["kernel"] == "OnlineMap" and report["method"]["online"]["scans"] == len(POSES)
    assert report["method"]["online"]["init_new"] == "ogm"  # the offline chain's start (init=ogm)
    assert "snapshots.npz" in report["files"]
    with np.load(out / "snapshots.npz", allow_pickle=False) as z:
        assert z["scans"].tolist() == [2, 4] and z["probabilities"].shape == (2, *m["grid"].shape)
    g, p = m["grid"], m["probabilities"]
    wall, inside = g.world_to_cell([[4.02, 1.5], [2.0, 3.02]]), g.world_to_cell([[2.0, 1.0], [3.0, 2.5]])
    assert np.all(p[wall[:, 0], wall[:, 1]] > 0.6) and np.all(p[inside[:, 0], inside[:, 1]] < 0.3)
    assert main([*argv[:-2], "--snapshots", "2", "--out", str(tmp_path / "o2")]) == 2  # needs --online
    assert main([*argv[:4], "--method", "p21", "--online", "--out", str(tmp_path / "o3")]) == 2  # not gibbs
    assert main([*argv[:-2], "--online", "--param", "init=prior", "--out", str(tmp_path / "o4")]) == 2
    assert main([*argv[:-2], "--online", "--param", "init=free", "--out", str(tmp_path / "o5")]) == 0
    report = __import__("json").loads((tmp_path / "o5" / "report.json").read_text())
    assert report["method"]["online"]["init_new"] == "keep"


def test_init_new_hits_starts_first_seen_cells_from_the_scan():
    grid, scans = _scene(num_scans=2)
    om = OnlineMap(grid, GaussianRange(1.0), _prior("independent", (N, N)), sweeps_per_scan=0, init_new="hits")
    om.add_scans(_part(scans, 0, 1))
    rays = raycast(grid, _part(scans, 0, 1))
    hit = np.zeros(grid.num_cells, bool)
    hit[rays.endpoint_cells()] = True
    expect = hit & ~om.pinned.numpy()
    assert np.array_equal(om.state.numpy().astype(bool), expect)
    _assert_same_as_rebuilt(om, grid, _part(scans, 0, 1), GaussianRange(1.0), _prior("independent", (N, N)))
    with pytest.raises(ValueError, match="init_new"):
        OnlineMap(grid, GaussianRange(1.0), _prior("independent", (N, N)), init_new="thresholded")
    with pytest.raises(AttributeError, match="init_new='ogm'"):
        _ = om.evidence  # kept only where it is used


@pytest.mark.parametrize("prior_name", ["independent", "mrf"])
def test_init_new_ogm_restarts_reached_cells_from_thresholded_ogm_of_all_scans(prior_name):
    """After each add, every latent cell the new rays reach holds the offline chains' thresholded-OGM start
    over all scans so far (initial_map of a rebuilt model); cells no new ray reaches keep their state; the
    kept evidence equals traditional OGM over all scans; the kept state equals a rebuild's."""
    from ogm_ppl.inference.log_odds.maps import evidence_grid
    from ogm_ppl.inference.mcmc.kernel import initial_map
    from ogm_ppl.models.delta import Moravec

    grid, scans = _scene(num_scans=4)
    sensor, prior = GaussianRange(1.0), _prior(prior_name, (N, N))
    om = OnlineMap(grid, sensor, prior, sweeps_per_scan=1, full_every=0, init_new="ogm", seed=2)
    for n in range(1, 5):
        before = om.state.numpy().copy()
        om.add_scans(_part(scans, n - 1, n), sweeps=0)
        so_far = _part(scans, 0, n)
        model = OccupancyModel(grid, raycast(grid, so_far), sensor, prior)
        start = initial_map(model).numpy()
        reached = raycast(grid, _part(scans, n - 1, n)).reached() & ~om.pinned.numpy()
        state = om.state.numpy()
        assert np.array_equal(state[reached], start[reached]), n
        assert np.array_equal(state[~reached & ~om.pinned.numpy()], before[~reached & ~om.pinned.numpy()])
        # the same additions in the same (reading) order as traditional OGM over all scans: bit for bit
        lo = evidence_grid(model.rays, Moravec.haehnel(), check_setting=False).log_odds.numpy()
        assert np.array_equal(om.evidence.numpy(), lo)
        _assert_same_as_rebuilt(om, grid, so_far, sensor, prior)
        om.sweep(1)  # the chain moves on before the next scan
