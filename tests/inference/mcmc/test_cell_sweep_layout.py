"""The compiled single-cell sweeps (``_kernels.cell_sweep``: every cell's likelihood ratio kept in fixed
point and updated when a ray's first or second hit moves, ``exp``-free decisions far from 0) are
bit-for-bit the straightforward sweep, which this file keeps as plain Python (it sums the rays through
the cell from scratch at every visit, in the same fixed point): same flips, same map, same first hits,
for every scan, both update rules, an independent and a correlated prior, from ordinary and from
impossible states (``-inf`` likelihoods). The kept sums equal the sums from scratch after every flip,
and differ from the floating-point sums by no more than the rounding bound."""

import math
from itertools import permutations

import numpy as np
import pytest

from ogm_ppl import GaussianRange, Grid, OccupancyModel, raycast
from ogm_ppl.datasets import simulate_scans
from ogm_ppl.inference._kernels import cell_sweep as cs
from ogm_ppl.inference._kernels.cells import first_hits
from ogm_ppl.priors import IndependentPrior, MRFPrior

N = 24


def scene(prior):
    rng = np.random.default_rng(5)
    truth = np.zeros((N, N), bool)
    truth[0, :] = truth[-1, :] = truth[:, 0] = truth[:, -1] = True
    truth[8, 4:15] = truth[6:20, 17] = True
    grid = Grid((N, N), resolution=0.1)
    free = np.argwhere(~truth)
    pick = free[rng.choice(len(free), 4, replace=False)]
    poses = np.c_[(pick[:, 1] + 0.5) * 0.1, (pick[:, 0] + 0.5) * 0.1, rng.uniform(-np.pi, np.pi, 4)]
    scans = simulate_scans(grid, truth, poses, np.arange(90) * (2 * np.pi / 90), 1.6, 1.0, 3)
    return OccupancyModel(grid, raycast(grid, scans), GaussianRange(1.0), prior)


def arrays(model, holes=0.0):
    """The index and the likelihood table; ``holes``: the share of table entries set to ``-inf``
    (impossible readings, which a sensor model with bounded support has); ``None``: every entry a ray
    uses made finite (the kernels' path for tables without impossible readings)."""
    r = model.rays
    idx = r.by_cell
    ll = model.loglik_table.numpy().copy()
    if holes is None:
        ll[np.isneginf(ll)] = -1e3
    else:
        ll[np.random.default_rng(9).random(ll.shape) < holes] = -np.inf
    return r.offsets, r.cells, idx.offsets, idx.ray, idx.kappa, ll


def next_occupied(arr, m, r, start):
    offsets, cells = arr[0], arr[1]
    a, n = offsets[r], offsets[r + 1] - offsets[r]
    for j in range(start, n):
        if m[cells[a + j]]:
            return j
    return n


def plain_ratio(arr, m, f, k, scale):
    """The likelihood ratio of cell ``k`` summed from scratch: rays blocked before ``k`` skipped, the next
    occupied cell looked up along the ray when ``k`` is its first hit; each finite entry rounded to
    ``rint(x * scale)`` (Python integers: no overflow), infinite terms counted, ``-inf - -inf`` skipped."""
    _, _, c_off, c_ray, c_kappa, ll = arr
    total, pos, neg = 0, 0, 0
    for p in range(c_off[k], c_off[k + 1]):
        r, kap = c_ray[p], c_kappa[p]
        if f[r] < kap:
            continue
        x, y = float(ll[r, kap]), float(ll[r, f[r] if f[r] > kap else next_occupied(arr, m, r, kap + 1)])
        if x > -math.inf and y > -math.inf:
            total += int(np.rint(x * scale)) - int(np.rint(y * scale))
        elif x > -math.inf:
            pos += 1
        elif y > -math.inf:
            neg += 1
    if pos:
        return math.nan if neg else math.inf
    return -math.inf if neg else total / scale


def plain_sweep(arr, m, f, order, uniforms, update, scale, prior_lo=None, lp=None):
    """The straightforward single-cell sweep (:func:`plain_ratio` at every visit). Mutates ``m`` and ``f``."""
    _, _, c_off, c_ray, c_kappa, _ = arr
    flips = 0
    for i, k in enumerate(order):
        lo = (prior_lo[k] if lp is None else cs.prior_log_odds(lp, k, m)) + plain_ratio(arr, m, f, k, scale)
        v = plain_new_value(lo, uniforms[i], int(m[k]), update)
        if v != m[k]:
            m[k] = v
            flips += 1
            for p in range(c_off[k], c_off[k + 1]):
                r, kap = c_ray[p], c_kappa[p]
                if v and kap < f[r]:
                    f[r] = kap
                elif not v and f[r] == kap:
                    f[r] = next_occupied(arr, m, r, kap + 1)
    return flips


def plain_new_value(lo, u, cur, update):
    if lo != lo:
        return 1 if u < 0.5 else 0
    if update == cs.METROPOLISED:
        d = -lo if cur else lo
        return 1 - cur if d >= 0.0 or (d > -math.inf and u < math.exp(d)) else cur
    if lo >= 0.0:
        return 1 if u * (1.0 + math.exp(-lo)) < 1.0 else 0
    e = math.exp(lo)
    return 1 if u * (1.0 + e) < e else 0


def compiled_state(arr, m):
    offsets, cells, c_off, c_ray, c_kappa, ll = arr
    return cs.cell_state(m, offsets, cells, c_off, c_ray, c_kappa, ll)


def orders(latent, rng):
    return {
        "systematic": latent,
        "permutation": np.ascontiguousarray(latent[rng.permutation(len(latent))]),
        "random": np.ascontiguousarray(latent[rng.integers(0, len(latent), len(latent))]),
    }


def second_hits(arr, m, f):
    lengths = np.diff(arr[0])
    return np.array([next_occupied(arr, m, r, f[r] + 1) if f[r] < lengths[r] else lengths[r] for r in range(len(f))])


@pytest.mark.parametrize("update", [cs.HEAT_BATH, cs.METROPOLISED])
@pytest.mark.parametrize("prior", ["independent", "mrf"])
@pytest.mark.parametrize("start", ["ogm-like", "impossible"])
def test_compiled_sweeps_are_the_plain_sweep_bit_for_bit(update, prior, start):
    model = scene(IndependentPrior(0.3, N * N) if prior == "independent" else MRFPrior((N, N), psi=0.7))
    arr = arrays(model, holes=0.03)
    offsets, cells, _, c_ray, c_kappa, ll = arr
    rng = np.random.default_rng(11)
    latent = model.latent.numpy().astype(np.int64)
    lo = model.prior.cell_log_odds()
    prior_lo = None if lo is None else np.ascontiguousarray(lo.numpy(), dtype=np.float64)
    lp = None if lo is not None else model.prior.compiled()
    bundle = model.prior.compiled()
    m0 = (rng.random(N * N) < (0.08 if start == "ogm-like" else 0.5)).astype(np.uint8)
    m0[model.known_free.numpy()] = 0
    f0 = first_hits(m0, offsets, cells)
    assert start == "ogm-like" or np.isinf(ll[np.arange(len(f0)), f0]).any()  # impossible readings present
    assert np.isinf(ll[c_ray, c_kappa]).any()  # and impossible first hits
    for name, order in orders(latent, rng).items():
        m_plain, f_plain = m0.copy(), f0.copy()
        st = compiled_state(arr, m0.copy())
        assert st.any_inf
        for sweep in range(4):
            u = rng.random(len(order))
            if sweep == 3:
                u[::7] = 0.0  # the smallest uniforms: the exp-free shortcuts must not decide these
            a = plain_sweep(arr, m_plain, f_plain, order, u, update, st.scale, prior_lo, lp)
            b = cs.sweep(st, order, bundle, u, update)
            assert a == b, (name, sweep)
            assert np.array_equal(st.m, m_plain) and np.array_equal(st.rays["f"], f_plain), (name, sweep)
            assert np.array_equal(st.rays["s"], second_hits(arr, m_plain, f_plain)), (name, sweep)
        assert a > 0


@pytest.mark.parametrize("holes", [None, 0.0, 0.03])
def test_kept_sums_are_the_sums_from_scratch_after_every_flip(holes):
    """Exact arithmetic: whatever sequence of flips, each kept ``d_k`` (and count of infinite terms) is
    the one a fresh state computes, and the ratio is :func:`plain_ratio`'s."""
    model = scene(IndependentPrior(0.3, N * N))
    arr = arrays(model, holes=holes)
    offsets, cells = arr[:2]
    rng = np.random.default_rng(3)
    m = (rng.random(N * N) < 0.25).astype(np.uint8)
    m[model.known_free.numpy()] = 0
    st = compiled_state(arr, m.copy())
    assert st.any_inf == (holes is not None)  # the model's own table has impossible readings (a hit read as none)
    latent = model.latent.numpy()
    for step, k in enumerate(rng.choice(latent, 400)):
        cs.set_cell(st, int(k), 1 - int(st.m[k]))
        fresh = compiled_state(arr, st.m.copy())
        assert np.array_equal(st.d, fresh.d) and np.array_equal(st.inf, fresh.inf), step
        assert np.array_equal(st.rays, fresh.rays), step
    f = first_hits(st.m, offsets, cells)
    for k in range(N * N):
        got, want = cs.log_lik_ratio(st, k), plain_ratio(arr, st.m, f, k, st.scale)
        assert got == want or (got != got and want != want), k


def test_ratios_are_within_the_rounding_bound_of_the_floating_point_sum():
    """``|kept - float sum| <= n_k 2^-S`` (each of a term's two entries rounds by at most 2^-S / 2), plus
    the float sum's own rounding."""
    model = scene(IndependentPrior(0.3, N * N))
    arr = arrays(model, holes=None)
    offsets, cells, c_off, c_ray, c_kappa, ll = arr
    m = (np.random.default_rng(2).random(N * N) < 0.2).astype(np.uint8)
    m[model.known_free.numpy()] = 0
    st = compiled_state(arr, m)
    f = first_hits(m, offsets, cells)
    for k in range(N * N):
        d, mag = 0.0, 0.0
        for p in range(c_off[k], c_off[k + 1]):
            r, kap = c_ray[p], c_kappa[p]
            if f[r] < kap:
                continue
            y = ll[r, f[r]] if f[r] > kap else ll[r, next_occupied(arr, m, r, kap + 1)]
            d += ll[r, kap] - y
            mag += abs(ll[r, kap]) + abs(y)
        n = c_off[k + 1] - c_off[k]
        assert abs(cs.log_lik_ratio(st, k) - d) <= n / st.scale + 4 * n * np.finfo(float).eps * mag, k


def test_fixed_point_bits_refuses_what_it_cannot_hold():
    c_off = np.array([0, 2, 3])
    ll = np.zeros((2, 3))
    assert cs.fixed_point_bits(ll, c_off) == 60  # nothing to hold: as fine as the format allows
    ll[0, 0] = -300.0
    bits = cs.fixed_point_bits(ll, c_off)
    assert 2 * (2 * 300 * 2.0**bits + 1) + 1 <= 2.0**62 < 2 * (2 * 300 * 2.0 ** (bits + 1) + 1) + 1
    ll[1, 2] = -np.inf  # an impossible reading is fine
    assert cs.fixed_point_bits(ll, c_off) == bits
    for bad in (np.inf, np.nan):
        ll[1, 1] = bad
        with pytest.raises(ValueError, match="ray 1, kappa 1"):
            cs.fixed_point_bits(ll, c_off)
    ll[1, 1] = -1e40
    with pytest.raises(ValueError, match="fraction bits"):
        cs.fixed_point_bits(ll, c_off)


def test_draws_orders_and_uniforms():
    cells = np.array([3, 7, 11, 20], dtype=np.int64)
    seed = np.uint64(12345)
    order, u = cs.draws(cells, cs.SYSTEMATIC, seed)
    assert order is cells or np.array_equal(order, cells)
    o2, u2 = cs.draws(cells, cs.PERMUTATION, seed)
    assert np.array_equal(u, u2) and sorted(o2) == sorted(cells)  # same seed, same uniforms
    assert np.array_equal(cs.draws(cells, cs.PERMUTATION, seed)[0], o2)  # and the same order
    o3 = cs.draws(cells, cs.RANDOM, seed)[0]
    assert np.isin(o3, cells).all()
    # uniforms: mean and variance of 10^6 draws within 6 standard errors of 1/2 and 1/12
    big = cs.draws(np.arange(10**6), cs.SYSTEMATIC, np.uint64(7))[1]
    assert ((big >= 0) & (big < 1)).all()
    assert abs(big.mean() - 0.5) < 6 * math.sqrt(1 / 12 / 1e6)
    assert abs(big.var() - 1 / 12) < 6 * math.sqrt(1 / 180 / 1e6)
    # every permutation of 4 cells, and every cell of a random scan, about equally often over 24,000 seeds
    T = 24_000
    perms = {p: 0 for p in permutations(range(4))}
    picks = np.zeros(4)
    for s in range(T):
        perms[tuple(cs.draws(np.arange(4), cs.PERMUTATION, np.uint64(s))[0])] += 1
        picks += np.bincount(cs.draws(np.arange(4), cs.RANDOM, np.uint64(s + T))[0], minlength=4)
    p = 1 / 24
    assert all(abs(c - T * p) < 6 * math.sqrt(T * p * (1 - p)) for c in perms.values()), perms
    assert np.all(np.abs(picks - T) < 6 * math.sqrt(4 * T * 0.25 * 0.75)), picks


def test_new_value_shortcuts_are_exact():
    los = [
        -math.inf,
        -800.0,
        -745.2,
        -41.0,
        -40.0000001,
        -40.0,
        -39.99,
        -20.0,
        -1e-300,
        -0.0,
        0.0,
        1e-300,
        20.0,
        39.99,
        40.0,
        40.0000001,
        41.0,
        800.0,
        math.inf,
        math.nan,
    ]
    us = [0.0, 5e-324, 1e-20, 4.2e-18, 4.25e-18, 4.2483542552915889e-18, 4.3e-18, 1e-17, 0.25, 0.5, 0.9999999999999999]
    for update in (cs.HEAT_BATH, cs.METROPOLISED):
        for lo in los:
            for u in us:
                for cur in (0, 1):
                    assert cs.new_value(lo, u, cur, update) == plain_new_value(lo, u, cur, update), (update, lo, u, cur)
