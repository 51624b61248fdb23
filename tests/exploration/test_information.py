"""Information gain from posterior samples against exact mutual information on enumerable problems."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
import torch

from ogm_ppl import GaussianRange, Grid, PatternMatch
from ogm_ppl.exploration import (
    beam_information,
    candidate_rays,
    expected_new_cells,
    first_hit_distribution,
    independent_first_hits,
    independent_information,
    reading_distribution,
    scan_information,
)
from ogm_ppl.inference.exact import brute_force
from ogm_ppl.posterior import first_hit_independent
from ogm_ppl.testing.kernels import enumerable_2d, enumerate_maps

LN2 = math.log(2.0)
# candidates on the 2 x 4 grid of enumerable_2d: cell (0, 2) is latent (its occupancy is conditioned on),
# cell (1, 1) too; beams along the rows, the columns and a diagonal
POSES = np.array([[2.5, 0.5, 0.0], [1.5, 1.5, -0.3]])
ANGLES = np.array([0.0, math.pi / 2, math.pi, -math.pi / 2, math.pi / 4])
MAX_RANGE = 3.0


# ------------------------------------------------------------------ references (plain torch, no kernels)
def ref_rows(sensor, f, none, F, w=1.0):
    """Reading-outcome probabilities from the sensor's formulas (``ogm_ppl.sensors``), torch.special.ndtr."""
    if isinstance(sensor, PatternMatch):
        n = int(F) + 2
        p = sensor.p_occ
        row = torch.full((n,), (1 - p) / (F + 1), dtype=torch.float64)
        row[n - 1 if none else int(f)] = p
        return row
    s, pr = float(sensor.sigma), sensor.p_rand
    J = math.ceil((F + 1) / w - 1e-12)
    e = torch.tensor([-0.5 + j * w for j in range(J + 1)], dtype=torch.float64)
    e[J] = F + 0.5
    length = e[1:] - e[:-1]
    unif = pr * length / (F + 1)
    if none:
        return torch.cat([unif, torch.tensor([1 - pr])])
    cdf = torch.special.ndtr((e - f) / s)
    cdf[0] = 0.0
    hit = (1 - pr) * (cdf[1:] - cdf[:-1]) + unif
    return torch.cat([hit, ((1 - pr) * (1 - torch.special.ndtr(torch.tensor((F + 0.5 - f) / s))))[None]])


def ref_map_rows(cr, sensor, maps, c, b, w=1.0):
    """``P(z_b = j | m)`` for every map (``M x outcomes``), first hits found by walking the ray."""
    r = c * cr.num_beams + b
    cells = cr.ray(c, b)
    t = cr.t_enter[cr.offsets[r] : cr.offsets[r + 1]].astype(np.float64)
    F = cr.max_range_cells if isinstance(sensor, GaussianRange) else float(max(cr.range_len[r], len(cells)) - 1)
    rows = []
    for m in maps:
        hits = [k for k in range(1, len(cells)) if m[cells[k]] == 1]
        if not hits:
            rows.append(ref_rows(sensor, 0.0, True, F, w))
        else:
            k = hits[0]
            rows.append(ref_rows(sensor, t[k] + 0.5 if isinstance(sensor, GaussianRange) else k, False, F, w))
    return torch.stack(rows)


def mi_bits(pi, rows):
    """``I(m; z)`` from map weights ``M`` and reading rows ``M x J``, enumerating maps (not first hits)."""
    q = pi @ rows
    ok = rows > 0
    t = torch.where(ok, rows * torch.log(torch.where(ok, rows, 1.0) / q), 0.0)
    return float((pi[:, None] * t).sum()) / LN2


@pytest.fixture(scope="module")
def problem():
    torch.set_default_dtype(torch.float64)
    model = enumerable_2d()
    maps = enumerate_maps(model)
    pi = brute_force(model).log_probs.exp()
    cr = candidate_rays(model.grid, POSES, ANGLES, MAX_RANGE)
    return model, maps, pi, cr


def conditioned(pi, maps, cr, c):
    keep = maps[:, int(cr.pose_cells[c])] == 0
    p = torch.where(keep, pi, 0.0)
    return p / p.sum()


# ------------------------------------------------------------------ reading model
@pytest.mark.parametrize("sensor", [GaussianRange(0.9), GaussianRange(0.6, p_rand=0.1)])
@pytest.mark.parametrize("w", [1.0, 0.35])
def test_reading_bins_integrate_the_sensor_density(sensor, w):
    F = 7.3
    f = torch.tensor([0.7, 3.2, 7.6, float("nan")])
    rows = reading_distribution(sensor, f, F, bin_width=w)
    torch.testing.assert_close(rows.sum(1), torch.ones(4), rtol=0, atol=1e-12)
    J = rows.shape[1] - 1
    for i, fi in enumerate(f.tolist()):
        none = math.isnan(fi)
        fv = F + 1 if none else fi
        mx = sensor.log_prob(torch.tensor(0.0), torch.tensor(fv), torch.tensor(F), torch.tensor(True)).exp()
        assert abs(float(rows[i, J]) - float(mx)) < 1e-12
        # every bin by the trapezoid rule on 20001 points (bin 0 from -1/2 - 12 sigma, split at -1/2 where the
        # uniform part starts), all bins in one call of the sensor's density
        lo = torch.tensor([-0.5 + j * w for j in range(J)])
        hi = torch.clamp(lo + w, max=F + 0.5)
        t = torch.linspace(0, 1, 20001)
        z = lo[:, None] + (hi - lo)[:, None] * t
        z0 = -0.5 - 12 * float(sensor.sigma) + (12 * float(sensor.sigma) - 1e-12) * t
        dens = sensor.log_prob(torch.cat([z, z0[None]]), torch.tensor(fv), torch.tensor(F)).exp()
        integral = torch.trapezoid(dens, torch.cat([z, z0[None]]), dim=1)
        integral[0] += integral[-1]
        assert (rows[i, :J] - integral[:J]).abs().max() < 2e-7, i


def test_pattern_match_outcomes_are_the_sensors_probabilities():
    sensor = PatternMatch(0.7)
    F = 4.0
    rows = reading_distribution(sensor, [0, 2, float("nan")], F)
    for i, f in enumerate([0.0, 2.0, F + 1]):
        z = torch.arange(F + 2)
        lp = sensor.log_prob(z, torch.tensor(f), torch.tensor(F), z == F + 1)
        torch.testing.assert_close(rows[i], lp.exp(), rtol=0, atol=1e-14)


# ------------------------------------------------------------------ per beam
@pytest.mark.parametrize("sensor", [GaussianRange(0.9), GaussianRange(0.5, p_rand=0.2), PatternMatch(0.8)])
def test_beam_information_is_the_exact_mi_under_the_exact_posterior(problem, sensor):
    model, maps, pi, cr = problem
    got = beam_information(model.grid, sensor, maps.to(torch.uint8), cr, weights=pi)
    assert got.shape == (len(POSES), len(ANGLES))
    for c in range(len(POSES)):
        pc = conditioned(pi, maps, cr, c)
        for b in range(len(ANGLES)):
            exact = mi_bits(pc, ref_map_rows(cr, sensor, maps, c, b))
            assert abs(float(got[c, b]) - exact) < 1e-10, (c, b, float(got[c, b]), exact)
    assert (got > 1e-3).any()


def test_repeated_samples_equal_their_weights(problem):
    model, maps, pi, cr = problem
    g = torch.Generator().manual_seed(3)
    idx = torch.multinomial(pi, 300, replacement=True, generator=g)  # 300 samples: five 64-bit words
    counts = torch.bincount(idx, minlength=len(pi)).double()
    sensor = GaussianRange(0.7)
    a = beam_information(model.grid, sensor, maps[idx].bool(), cr)
    b = beam_information(model.grid, sensor, maps, cr, weights=counts)
    torch.testing.assert_close(a, b, rtol=0, atol=1e-12)
    grid_shaped = maps.reshape(len(maps), *model.grid.shape)  # as grid-shaped marginals are taken too
    torch.testing.assert_close(beam_information(model.grid, sensor, grid_shaped, cr, weights=counts), b, rtol=0, atol=0)
    pf = first_hit_distribution(model.grid, maps[idx], cr)
    for c in range(len(POSES)):
        keep = maps[idx][:, int(cr.pose_cells[c])] == 0
        for bb in range(len(ANGLES)):
            r = c * len(ANGLES) + bb
            cells = cr.ray(c, bb)
            n = len(cells)
            occ = torch.cat([maps[idx][keep][:, torch.from_numpy(cells[1:])] == 1, torch.ones(int(keep.sum()), 1,
                            dtype=torch.bool)], 1)  # fmt: skip
            f = occ.to(torch.uint8).argmax(1) + 1  # the sentinel column: none on the ray (kappa n)
            expect = torch.bincount(f, minlength=n + 1).double() / keep.sum()
            torch.testing.assert_close(pf[r, : n + 1], expect, rtol=0, atol=1e-14)
            assert (pf[r, n + 1 :] == 0).all()


def test_beam_information_of_posterior_draws_converges_to_the_exact_mi(problem):
    """S exact posterior draws: the plug-in error is within 5 delta-method standard deviations
    ``sqrt(Var_m[D(p(z | m) || p(z))] / S)`` plus an O(1/S) bias allowance."""
    model, maps, pi, cr = problem
    sensor = GaussianRange(0.9)
    S = 20000
    idx = torch.multinomial(pi, S, replacement=True, generator=torch.Generator().manual_seed(8))
    got = beam_information(model.grid, sensor, maps[idx].to(torch.uint8), cr)
    worst = 0.0
    for c in range(len(POSES)):
        pc = conditioned(pi, maps, cr, c)
        n_kept = int((maps[idx][:, int(cr.pose_cells[c])] == 0).sum())
        for b in range(len(ANGLES)):
            rows = ref_map_rows(cr, sensor, maps, c, b)
            q = pc @ rows
            d = torch.where(rows > 0, rows * torch.log(torch.where(rows > 0, rows, 1.0) / q), 0.0).sum(1) / LN2
            exact = float(pc @ d)
            sd = math.sqrt(float(pc @ (d - exact) ** 2) / n_kept)
            err = abs(float(got[c, b]) - exact)
            assert err < 5 * sd + rows.shape[1] / n_kept / LN2, (c, b, err, sd)
            worst = max(worst, err)
    assert worst > 0  # the draws are not the exact weights


def test_finer_bins_never_lose_information_and_converge(problem):
    model, maps, pi, cr = problem
    sensor = GaussianRange(0.8)
    vals = [beam_information(model.grid, sensor, maps, cr, weights=pi, bin_width=w) for w in (1, 0.5, 0.25, 1 / 64)]
    for coarse, fine in itertools.pairwise(vals):
        assert (fine >= coarse - 1e-12).all()
    assert (vals[1] - vals[0]).max() > 1e-3  # refinement matters here, so the check above can fail
    fine2 = beam_information(model.grid, sensor, maps, cr, weights=pi, bin_width=1 / 128)
    assert (fine2 - vals[-1]).abs().max() < 1e-4


# ------------------------------------------------------------------ whole scan
def exact_scan_mi(pi, rows_per_beam):
    """``I(m; z_1..z_B)`` by enumerating every reading tuple: rows_per_beam are ``M x J_b``."""
    M = len(pi)
    joint = torch.ones(M, 1, dtype=torch.float64)
    for rows in rows_per_beam:
        joint = (joint[:, :, None] * rows[:, None, :]).reshape(M, -1)
    return mi_bits(pi, joint)


@pytest.mark.parametrize(
    "sensor, w", [(PatternMatch(0.75), None), (GaussianRange(0.8), 1.0), (GaussianRange(0.6, p_rand=0.15), 1.0)]
)
def test_scan_estimator_is_within_its_standard_error_of_the_exact_mi(problem, sensor, w):
    model, maps, pi, _cr3 = problem
    beams = np.array([0.0, 0.05, math.pi / 2])  # two beams along one row: redundant through the map
    cr = candidate_rays(model.grid, POSES, beams, MAX_RANGE)
    res = scan_information(
        model.grid, sensor, maps, cr, num_draws=4000, generator=torch.Generator().manual_seed(11), weights=pi,
        bin_width=w,
    )  # fmt: skip
    per_beam = beam_information(model.grid, sensor, maps, cr, weights=pi, bin_width=w)
    for c in range(len(POSES)):
        pc = conditioned(pi, maps, cr, c)
        exact = exact_scan_mi(pc, [ref_map_rows(cr, sensor, maps, c, b) for b in range(len(beams))])
        se = float(res.stderr[c])
        assert 0 < se < 0.03
        assert abs(float(res.mean[c]) - exact) < 4 * se, (c, float(res.mean[c]), exact, se)
        # beams share the map: the scan's information is not the sum of the beams'
        assert exact <= float(per_beam[c].sum()) + 1e-12
    assert any(
        float(per_beam[c].sum()) - exact_scan_mi(conditioned(pi, maps, cr, c), [
            ref_map_rows(cr, sensor, maps, c, b) for b in range(len(beams))]) > 0.05
        for c in range(len(POSES))
    )  # fmt: skip


def test_scan_estimator_of_continuous_readings_matches_the_fine_bin_limit(problem):
    model, maps, pi, _cr = problem
    sensor = GaussianRange(0.7, p_rand=0.05)
    one = candidate_rays(model.grid, POSES, np.array([math.pi / 4]), MAX_RANGE)
    res = scan_information(model.grid, sensor, maps, one, num_draws=6000, generator=torch.Generator().manual_seed(2),
                           weights=pi)  # fmt: skip
    limit = beam_information(model.grid, sensor, maps, one, weights=pi, bin_width=1 / 128)[:, 0]
    assert (res.stderr < 0.02).all()
    assert ((res.mean - limit).abs() < 4 * res.stderr + 1e-3).all(), (res.mean, limit, res.stderr)


def test_scan_with_a_seed_is_reproducible(problem):
    model, maps, _pi, cr = problem
    run = [
        scan_information(model.grid, GaussianRange(0.8), maps[:50], cr, num_draws=64,
                         generator=torch.Generator().manual_seed(5))
        for _ in range(2)
    ]  # fmt: skip
    assert torch.equal(run[0].mean, run[1].mean) and torch.equal(run[0].stderr, run[1].stderr)


# ------------------------------------------------------------------ independent-cell baseline
def test_independent_information_equals_enumerating_the_product_distribution():
    grid = Grid((3, 7), resolution=0.5)
    g = torch.Generator().manual_seed(0)
    marg = torch.rand(grid.num_cells, generator=g, dtype=torch.float64) * 0.8 + 0.1
    cr = candidate_rays(grid, [[0.25, 0.75, 0.0], [1.6, 0.3, 2.0]], [0.0, 0.4, -1.1], max_range=3.1)
    for sensor in (GaussianRange(0.7, p_rand=0.05), PatternMatch(0.6)):
        got = independent_information(grid, sensor, marg, cr)
        for c in range(2):
            for b in range(3):
                cells = cr.ray(c, b)
                n = len(cells)
                assert n <= 12
                # every configuration of the beam's cells after the sensor's, under the product distribution
                bits = ((torch.arange(2 ** (n - 1))[:, None] >> torch.arange(n - 1)) & 1).double()
                p = marg[torch.from_numpy(cells[1:])]
                pi = (bits * p + (1 - bits) * (1 - p)).prod(1)
                maps = torch.zeros(len(bits), grid.num_cells, dtype=torch.float64)
                maps[:, torch.from_numpy(cells[1:])] = bits
                exact = mi_bits(pi, ref_map_rows(cr, sensor, maps, c, b))
                assert abs(float(got[c, b]) - exact) < 1e-10, (c, b)
                # its first-hit distribution is Eq. (4.7) with the sensor's own cell free
                pf = independent_first_hits(grid, marg, cr)[c * 3 + b, : n + 1]
                q = marg[torch.from_numpy(cells)].clone()
                q[0] = 0.0
                torch.testing.assert_close(pf, first_hit_independent(q), rtol=0, atol=1e-15)
        assert (got > 0.01).all()


def test_independent_information_of_sample_marginals_differs_from_the_samples(problem):
    """On a correlated posterior, the baseline on the samples' marginals is not the samples' information."""
    model, maps, pi, cr = problem
    sensor = GaussianRange(0.9)
    marg = pi @ maps
    ind = independent_information(model.grid, sensor, marg, cr)
    cor = beam_information(model.grid, sensor, maps, cr, weights=pi)
    assert ind.shape == cor.shape and (ind - cor).abs().max() > 1e-3


# ------------------------------------------------------------------ expected newly observed cells
def ref_new_cells(cr, maps, pi, observed, c, include_hit=False):
    """``E[|union_b V_b(m) minus O|]`` by walking every beam of candidate ``c`` in every map (plain Python)."""
    num = den = 0.0
    for m, w in zip(maps.tolist(), pi.tolist()):
        if m[int(cr.pose_cells[c])] == 1:
            continue
        seen = set()
        for b in range(cr.num_beams):
            for k, cell in enumerate(cr.ray(c, b).tolist()):
                if k > 0 and m[cell] == 1:
                    if include_hit and not observed[cell]:
                        seen.add(cell)
                    break
                if not observed[cell]:
                    seen.add(cell)
        num += w * len(seen)
        den += w
    return num / den


@pytest.mark.parametrize("include_hit", [False, True])
def test_expected_new_cells_equals_walking_every_beam_in_every_map(problem, include_hit):
    model, maps, pi, cr = problem
    grid = model.grid
    rng = np.random.default_rng(4)
    for observed in (np.zeros(grid.num_cells, bool), rng.random(grid.num_cells) < 0.4):
        got = expected_new_cells(grid, maps.to(torch.uint8), cr, observed, weights=pi, include_hit=include_hit)
        assert got.shape == (len(POSES),) and got.dtype == torch.float64
        for c in range(len(POSES)):
            exact = ref_new_cells(cr, maps, pi, observed, c, include_hit)
            assert abs(float(got[c]) - exact) < 1e-12, (c, float(got[c]), exact)
    # everything observed: nothing new; repeated samples equal their counts as weights (five 64-bit words)
    assert (expected_new_cells(grid, maps, cr, np.ones(grid.num_cells, bool), weights=pi) == 0).all()
    idx = torch.multinomial(pi, 300, replacement=True, generator=torch.Generator().manual_seed(1))
    counts = torch.bincount(idx, minlength=len(pi)).double()
    torch.testing.assert_close(
        expected_new_cells(grid, maps[idx], cr, observed, include_hit=include_hit),
        expected_new_cells(grid, maps, cr, observed, weights=counts, include_hit=include_hit),
        rtol=0,
        atol=1e-12,
    )


def test_expected_new_cells_counts_a_cell_two_beams_cross_once():
    """A free 1 x 6 row, a beam east twice: the 5 cells east of the sensor cell, and the sensor cell itself."""
    g = Grid((1, 6))
    cr = candidate_rays(g, [[0.5, 0.5, 0.0]], [0.0, 0.0], max_range=5.0)
    free = np.zeros((1, 6), np.uint8)
    assert float(expected_new_cells(g, free, cr, np.zeros(6, bool))[0]) == 6.0
    wall = free.copy()
    wall[0, 3] = 1  # the beam stops at cell 3: cells 0..2 seen (3 with the hit)
    both = np.concatenate([free, wall])
    assert float(expected_new_cells(g, both, cr, np.zeros(6, bool))[0]) == pytest.approx((6 + 3) / 2)
    assert float(expected_new_cells(g, both, cr, np.zeros(6, bool), include_hit=True)[0]) == pytest.approx(5.0)


def test_expected_new_cells_refuses_bad_input(problem):
    model, maps, _pi, cr = problem
    grid = model.grid
    obs = np.zeros(grid.num_cells, bool)
    with pytest.raises(ValueError, match="observed must be a mask of the grid's 8 cells"):
        expected_new_cells(grid, maps, cr, np.zeros(5, bool))
    with pytest.raises(ValueError, match="observed must hold only 0/1"):
        expected_new_cells(grid, maps, cr, np.full(grid.num_cells, 0.5))
    with pytest.raises(ValueError, match="samples is empty"):
        expected_new_cells(grid, np.zeros((0, grid.num_cells), np.uint8), cr, obs)
    with pytest.raises(ValueError, match=f"S x {grid.num_cells}"):
        expected_new_cells(grid, np.zeros((3, 5), np.uint8), cr, obs)
    with pytest.raises(ValueError, match=r"candidate pose 0 .* inside an obstacle.*every sample"):
        expected_new_cells(grid, maps[maps[:, int(cr.pose_cells[0])] == 1], cr, obs)
    with pytest.raises(ValueError, match="another grid"):
        expected_new_cells(Grid((2, 4), resolution=0.5), maps, cr, obs)
    with pytest.raises(ValueError, match="weights"):
        expected_new_cells(grid, maps, cr, obs, weights=torch.ones(3))


# ------------------------------------------------------------------ bad input
def test_bad_input_is_refused_with_what_is_wrong(problem):
    model, maps, _pi, cr = problem
    grid = model.grid
    s = GaussianRange(0.9)
    with pytest.raises(ValueError, match=r"candidate pose 1 .* off the grid"):
        candidate_rays(grid, [[0.5, 0.5, 0.0], [4.5, 0.5, 0.0]], ANGLES, MAX_RANGE)
    with pytest.raises(ValueError, match="candidate set is empty"):
        candidate_rays(grid, np.zeros((0, 3)), ANGLES, MAX_RANGE)
    with pytest.raises(ValueError, match="beam_angles"):
        candidate_rays(grid, POSES, [], MAX_RANGE)
    with pytest.raises(ValueError, match="max_range"):
        candidate_rays(grid, POSES, ANGLES, 0.0)
    occ = np.zeros(grid.num_cells, dtype=bool)
    occ[int(cr.pose_cells[1])] = True
    with pytest.raises(ValueError, match=r"candidate pose 1 .* inside an obstacle \(cell \[1, 1\]"):
        candidate_rays(grid, POSES, ANGLES, MAX_RANGE, occupied=occ)
    with pytest.raises(ValueError, match="samples is empty"):
        beam_information(grid, s, np.zeros((0, grid.num_cells), np.uint8), cr)
    with pytest.raises(ValueError, match="samples is empty"):
        scan_information(grid, s, np.zeros((0, grid.num_cells), np.uint8), cr)
    with pytest.raises(ValueError, match=f"S x {grid.num_cells}"):
        beam_information(grid, s, np.zeros((3, 5), np.uint8), cr)
    with pytest.raises(ValueError, match="only 0 and 1"):
        beam_information(grid, s, np.full((3, grid.num_cells), 2, np.uint8), cr)
    blocked = maps[maps[:, int(cr.pose_cells[0])] == 1]
    for fn in (beam_information, scan_information):
        with pytest.raises(ValueError, match=r"candidate pose 0 .* inside an obstacle.*every sample"):
            fn(grid, s, blocked, cr)
    m = torch.full((grid.num_cells,), 0.3)
    m[int(cr.pose_cells[1])] = 1.0
    with pytest.raises(ValueError, match=r"candidate pose 1 .* inside an obstacle.*marginals"):
        independent_information(grid, s, m, cr)
    with pytest.raises(ValueError, match="another grid"):
        beam_information(Grid((2, 4), resolution=0.5), s, maps, cr)
    with pytest.raises(ValueError, match="weights"):
        beam_information(grid, s, maps, cr, weights=torch.ones(3))
    with pytest.raises(ValueError, match="bin_width"):
        beam_information(grid, s, maps, cr, bin_width=0.0)
    with pytest.raises(TypeError, match="no compiled reading model"):
        beam_information(grid, object(), maps, cr)


def test_tabulated_normal_tail_matches_erfc():
    from ogm_ppl.sensors_compiled.normal import tail

    for x in np.concatenate([np.linspace(0, 12, 20011), np.random.default_rng(0).uniform(0, 10, 5000)]):
        exact = 0.5 * math.erfc(x / math.sqrt(2))
        assert abs(tail(x) / exact - 1) < 1e-13, x


def test_beam_information_survives_max_range_terms_that_underflow():
    """Two first hits a thousandth of a cell apart at the start of a 10-cell ray, sigma = 0.26 cells: each one's
    max-range probability is 5e-324, and times its first-hit probability it rounds to 0, so that outcome's
    total probability is 0 while its terms are not. The beam's information is still finite and at most the
    entropy of the first hit, log 2."""
    from ogm_ppl.exploration.beam_mi import beam_mi_kernel
    from ogm_ppl.exploration.rays import RayTable
    from ogm_ppl.sensors_compiled import GaussianReading

    F = 10.0
    sigma = F / (27.2 * math.sqrt(2.0))
    assert 0.0 < 0.5 * math.erfc(F / (sigma * math.sqrt(2.0))) < 1e-323
    pf = np.array([[0.5, 0.5, 0.0]])  # hits at kappa 0 and 1, never none
    # t_enter float32, the library's convention (RayTable), so the kernel is the one the library compiles
    t_enter = np.array([0.0, 0.001], np.float32)
    rays = RayTable(np.array([0, 2], np.int64), np.zeros(2, np.int64), t_enter, np.zeros(1, np.int64), 1)
    mi = beam_mi_kernel(pf, rays, np.array([F]), GaussianReading(sigma=sigma, p_rand=0.0, width=1.0))
    assert np.isfinite(mi).all() and 0.0 <= mi[0] <= math.log(2.0)
