"""Learning a pattern field: the sufficient statistics (unknown cells excluded), the pseudo-likelihood's
conditionals equal the compiled ones, parameter recovery by PL and by PCD from maps drawn by the
compiled sampler of a known field, the backoff centre equals the smaller field, the sampler check tells a
mixing field from a bistable one, and the tempering search recovers the power of a known field."""

import numpy as np
import pytest
import torch

from ogm_ppl.inference._kernels.cell_sweep import prior_log_odds
from ogm_ppl.priors.compiled import prior_gibbs_sweeps
from ogm_ppl.priors.compiled.field import pattern_field
from ogm_ppl.priors.learn_field import (
    backoff_potentials,
    data_crops,
    field_stats,
    fit_pcd,
    fit_pl,
    fit_tempered,
    sampler_check,
    unary_orbits,
)
from ogm_ppl.priors.learn_field._pl import _PL
from ogm_ppl.priors.learn_field._stats import _nbhd_keys
from ogm_ppl.priors.pattern_field import PatternFieldPrior, orbits_to_table, symmetry_orbits

W = 2
N_ORB = symmetry_orbits(W)[1]
TRUE = np.array([-0.6, 0.5, 0.2, -0.4, 0.3, 0.1])[:N_ORB]


def conditional_table(theta):
    """The identifiable quantity: the log-odds of an interior cell given each of its 256 neighbourhoods
    (3 x 3 windows of a w = 2 field: the four windows holding the cell)."""
    p = PatternFieldPrior((3, 3), theta, W)
    codes = np.arange(512)
    maps = ((codes[codes & 16 == 0][:, None] >> np.arange(9)) & 1).astype(np.uint8)
    return np.array([prior_log_odds(p.compiled(), 4, np.ascontiguousarray(m)) for m in maps]), maps


def samples(n, size, seed, sweeps=300):
    b = pattern_field(size, size, W, orbits_to_table(TRUE, W))
    rng = np.random.default_rng(seed)
    maps = np.ascontiguousarray(rng.random((n, size * size)) < 0.5, dtype=np.uint8)
    prior_gibbs_sweeps(b, maps, sweeps, seed)
    return [m.reshape(size, size).astype(bool) for m in maps]


def weighted_rms(est, maps_stats):
    """RMS error of the conditional table, weighted by how often each neighbourhood occurs in the data."""
    want, nb = conditional_table(TRUE)
    got, _ = conditional_table(est)
    S = 3
    key = (nb.astype(np.int64) << np.arange(9)).sum(1)
    freq = np.zeros(512)
    np.add.at(freq, maps_stats.keys1 & ~np.int64(1 << 4), maps_stats.counts1)
    wgt = freq[key] / freq[key].sum()
    assert S == 2 * W - 1
    return float(np.sqrt((wgt * (got - want) ** 2).sum())), float(np.sqrt((wgt * want**2).sum()))


def test_window_counts_skip_unknown_cells():
    rng = np.random.default_rng(0)
    occ = rng.random((7, 8)) < 0.4
    known = rng.random((7, 8)) < 0.85
    st = field_stats([(occ, known)], 2, 2)
    want = np.zeros(16, np.int64)
    for r in range(6):
        for c in range(7):
            if known[r : r + 2, c : c + 2].all():
                want[int(((occ & known)[r : r + 2, c : c + 2].ravel() << np.arange(4)).sum())] += 1
    np.testing.assert_array_equal(st.win1, want)
    # a cell counts in the PL sum only with its whole 3 x 3 neighbourhood known and inside the grid
    n_elig = sum(known[r - 1 : r + 2, c - 1 : c + 2].all() for r in range(1, 6) for c in range(1, 7))
    assert st.counts1.sum() == n_elig


def test_pl_conditionals_equal_the_compiled_ones():
    rng = np.random.default_rng(1)
    th1, th2 = rng.normal(size=N_ORB), rng.normal(size=N_ORB)
    p = PatternFieldPrior((6, 6), th1, W, th2)
    for _ in range(5):
        g = (rng.random((6, 6)) < 0.4).astype(np.uint8)
        k1, k2 = _nbhd_keys(g, np.zeros_like(g), W, True)
        cells1 = [r * 6 + c for r in range(1, 5) for c in range(1, 5)]
        cells2 = [r * 6 + c for r in (2, 3) for c in (2, 3)]  # the parent's pooled 3 x 3 inside the 3 x 3 pooled grid
        assert len(k1) == len(cells1) and len(k2) == len(cells2)
        m = np.ascontiguousarray(g.ravel())
        for keys, cells, scales in ((k2, cells2, 2), (k1, cells1, 1)):
            st = field_stats([], W, 2)
            st.keys1, st.counts1 = keys, np.ones(len(keys), np.int64)
            st.keys2, st.counts2 = keys, np.ones(len(keys), np.int64)
            pl = _PL(st, scales)
            got = pl.log_odds(torch.tensor(th1), torch.tensor(th2) if scales == 2 else None).numpy()
            q = p if scales == 2 else PatternFieldPrior((6, 6), th1, W)
            want = [prior_log_odds(q.compiled(), k, m) for k in cells]
            np.testing.assert_allclose(got, want, rtol=0, atol=1e-12)


def test_parameter_recovery_by_pl_and_pcd():
    # 24 maps of 40 x 40 from the known field (300 compiled sweeps from noise: the field mixes within a few
    # tens of sweeps), about 36,000 PL cells for 6 parameters: the standard error of a parameter is of order
    # 1 / sqrt(36000 / 6) ~ 0.013 and of a conditional (a sum of 4 differences) ~ 0.05, so 0.1 is a
    # 2-sigma-plus bound on the frequency-weighted RMS error; PCD adds the chains' Monte Carlo noise (0.15).
    train = field_stats(samples(24, 40, seed=1), W, 1)
    val = field_stats(samples(6, 40, seed=2), W, 1)
    th, _, _ = fit_pl(train, 1, lambda_=1e-6, progress=False)
    err, spread = weighted_rms(th, train)
    assert spread > 0.5  # the conditionals are far from 0: recovering them is not trivial
    assert err < 0.1, (err, th, TRUE)
    fit = fit_pcd(
        train,
        val,
        np.zeros(N_ORB),
        iterations=300,
        chains=8,
        size=40,
        lr=0.05,
        lambda_=1e-6,
        eval_every=20,
        seed=3,
        progress=False,
        init=data_crops(samples(8, 40, seed=4), 8, 40),
    )
    err_pcd, _ = weighted_rms(fit.theta, train)
    assert fit.best_iteration > 0 and err_pcd < 0.15, (err_pcd, fit.theta, TRUE, fit.curve)
    # and the zero field is far off: the tolerances separate a fit from no fit
    assert weighted_rms(np.zeros(N_ORB), train)[0] > 0.5


def test_backoff_potentials_give_the_small_field_away_from_the_edges():
    # every 2 x 2 window holding a cell at least 2 cells from the edges lies in four 3 x 3 windows of the
    # grid, so the cell's log-odds under the spread potentials equal those of the 2 x 2 field (exactly)
    rng = np.random.default_rng(5)
    phi = rng.normal(size=N_ORB)
    big = PatternFieldPrior((7, 8), backoff_potentials(phi, 2, 3), 3).compiled()
    small = PatternFieldPrior((7, 8), phi, 2).compiled()
    for _ in range(5):
        m = np.ascontiguousarray((rng.random(56) < 0.5).astype(np.uint8))
        for r in range(2, 5):
            for c in range(2, 6):
                k = r * 8 + c
                assert abs(prior_log_odds(big, k, m) - prior_log_odds(small, k, m)) < 1e-12
    # and a cell on the edge sees fewer windows: the two fields differ there (the check can fail)
    m = np.zeros(56, np.uint8)
    assert abs(prior_log_odds(big, 0, m) - prior_log_odds(small, 0, m)) > 1e-3


def test_sampler_check_tells_mixing_from_two_phases():
    # the zero field: independent fair cells; 4 chains x 16^2 centre cells x 10 reads 10 sweeps apart
    # (independent under the zero field) = 10,240 draws, standard error 0.005: 0.025 is 5 sigma
    rows = sampler_check(np.zeros(N_ORB), None, W, sizes=(32,), chains=4, sweeps=100, keep=100, seed=0)
    assert [r["start"] for r in rows] == ["free", "occupied"]
    for r in rows:
        assert abs(r["occupancy"] - 0.5) < 0.025, rows
    # a strongly coupled 2 x 2 field (uniform windows favoured by 3 nats): each start keeps its phase
    orb = symmetry_orbits(W)[0]
    phi = np.zeros(N_ORB)
    phi[[orb[0], orb[15]]] = 3.0
    rows = sampler_check(phi, None, W, sizes=(32,), chains=4, sweeps=100, seed=0)
    assert rows[0]["occupancy"] < 0.05 and rows[1]["occupancy"] > 0.95, rows
    # the gap to maps of the known field is small for it and large for the zero field
    ref = field_stats(samples(8, 40, seed=6), W, 1)
    g_true = sampler_check(TRUE, None, W, ref, sizes=(40,), chains=4, sweeps=150, seed=1)
    g_zero = sampler_check(np.zeros(N_ORB), None, W, ref, sizes=(40,), chains=4, sweeps=150, seed=1)
    assert max(r["gap"] for r in g_true) < 0.05 < 0.2 < min(r["gap"] for r in g_zero), (g_true, g_zero)


def test_fit_tempered_recovers_the_power_of_a_known_field(tmp_path):
    # handed TRUE / 0.8, the search over beta must pick 0.8: the known field mixes (both starts agree at
    # every beta here) and its window frequencies move by ~0.05 in L1 per 0.2 of beta, several times the
    # Monte Carlo spread of the gap (4 chains x 38^2 windows x 10 reads)
    val = field_stats(samples(8, 40, seed=7), W, 1)
    fit = fit_tempered(val, TRUE / 0.8, betas=(0.4, 0.6, 0.8, 1.0, 1.2), size=40, sweeps=150, seed=2, progress=False)
    assert fit.beta == 0.8, fit.curve
    np.testing.assert_allclose(fit.theta, TRUE, rtol=0, atol=1e-12)
    assert all(abs(c[2] - c[3]) <= 0.1 for c in fit.curve)
    # the fit becomes a prior, which save_field keeps and field_from_file reads back
    from ogm_ppl.priors.pattern_field import field_from_file, save_field

    with pytest.raises(TypeError, match=r"a FieldFit: pass fit.prior\(shape\)"):
        save_field(tmp_path / "f.npz", fit)
    prior = fit.prior((10, 12))
    back = field_from_file(save_field(tmp_path / "f.npz", prior), (10, 12))
    maps = torch.rand(5, 120, generator=torch.Generator().manual_seed(0), dtype=torch.float64) < 0.4
    torch.testing.assert_close(back.log_prob(maps.double()), prior.log_prob(maps.double()), rtol=0, atol=1e-9)


def test_unary_orbits_shift_every_interior_log_odds_by_the_bias():
    rng = np.random.default_rng(8)
    th = rng.normal(size=symmetry_orbits(3)[1])
    a = PatternFieldPrior((6, 7), th, 3).compiled()
    b = PatternFieldPrior((6, 7), th + 0.7 * unary_orbits(3), 3).compiled()
    m = np.ascontiguousarray((rng.random(42) < 0.5).astype(np.uint8))
    for r in range(2, 4):
        for c in range(2, 5):
            k = r * 7 + c
            assert abs(prior_log_odds(b, k, m) - prior_log_odds(a, k, m) - 0.7) < 1e-12


def test_fit_tempered_bias_reaches_the_target_occupancy():
    # the zero field has independent cells: P(m_k = 1) = sigmoid(b), so 6 bisection steps on [-1.5, 1.5]
    # put b within 3 / 64 ~ 0.05 of logit(0.3) = -0.85 (plus the Monte Carlo error of each step's
    # occupancy, s.e. 0.002 from 4 chains x 2 starts x 24^2 centre cells x 10 reads: 0.01 in logit), and
    # the final marginal within 0.02 of 0.3
    val = field_stats(samples(4, 40, seed=9), W, 1)
    fit = fit_tempered(
        val, np.zeros(N_ORB), betas=(1.0,), occupancy=0.3, bias_steps=6, size=40, sweeps=100, seed=3, progress=False
    )
    assert abs(fit.curve[0][4] - np.log(0.3 / 0.7)) < 0.1, fit.curve
    assert abs(fit.occupancy - 0.3) < 0.02, fit.curve
    np.testing.assert_allclose(fit.theta, fit.curve[0][4] * unary_orbits(W), rtol=0, atol=1e-12)


def test_fit_pattern_field_refuses_what_it_cannot_fit_on():
    from ogm_ppl.priors.learn_field import fit_pattern_field

    maps = samples(2, 20, seed=1)
    with pytest.raises(ValueError, match="no validation maps"):
        fit_pattern_field(maps, [], progress=False)
    with pytest.raises(ValueError, match="no training maps"):
        fit_pattern_field([], maps, progress=False)
    with pytest.raises(ValueError, match="the validation maps hold no 3 x 3 window of known cells"):
        fit_pattern_field(maps, [(np.zeros((5, 5), bool), np.zeros((5, 5), bool))], progress=False)
