"""The compiled single-cell sweeps (``_kernels.cell_sweep``: cached second hits, branch-free sums,
prefetching for jumping scans, ``exp``-free decisions far from 0) are bit-for-bit the straightforward
sweep, which this file keeps as plain Python: same flips, same map, same first hits and likelihoods,
for every scan, both update rules, an independent and a correlated prior, from ordinary and from
impossible states (``-inf`` likelihoods), and the second-hit cache never holds a stale entry."""

import math

import numpy as np
import pytest

from ogm_ppl import GaussianRange, Grid, OccupancyModel, raycast
from ogm_ppl.datasets import simulate_scans
from ogm_ppl.inference._kernels import cell_sweep as cs
from ogm_ppl.inference._kernels.cells import first_hits
from ogm_ppl.priors import IndependentPrior, MRFPrior
from ogm_ppl.priors.local import cell_log_odds, local_of

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
    (impossible readings, which a sensor model with bounded support has)."""
    r = model.rays
    idx = r.by_cell
    ll = model.loglik_table.numpy().copy()
    ll[np.random.default_rng(9).random(ll.shape) < holes] = -np.inf
    return r.offsets, r.cells, idx.offsets, idx.ray, idx.kappa, ll


def plain_sweep(arr, m, f, order, uniforms, update, prior_lo=None, lp=None):
    """The straightforward single-cell sweep: walk the rays through the cell, skip those blocked before it,
    look the next occupied cell up along the ray when the cell is a first hit. Mutates ``m`` and ``f``."""
    offsets, cells, c_off, c_ray, c_kappa, ll = arr

    def next_occupied(r, start):
        a, n = offsets[r], offsets[r + 1] - offsets[r]
        for j in range(start, n):
            if m[cells[a + j]]:
                return j
        return n

    flips = 0
    for i, k in enumerate(order):
        d = 0.0  # (Python floats: -inf - -inf is a quiet nan)
        for p in range(c_off[k], c_off[k + 1]):
            r, kap = c_ray[p], c_kappa[p]
            if f[r] < kap:
                continue
            t = float(ll[r, kap]) - float(ll[r, f[r]] if f[r] > kap else ll[r, next_occupied(r, kap + 1)])
            if t == t:
                d += t
        lo = (prior_lo[k] if lp is None else cell_log_odds(lp, k, m)) + d
        v = plain_new_value(lo, uniforms[i], int(m[k]), update)
        if v != m[k]:
            m[k] = v
            flips += 1
            for p in range(c_off[k], c_off[k + 1]):
                r, kap = c_ray[p], c_kappa[p]
                if v and kap < f[r]:
                    f[r] = kap
                elif not v and f[r] == kap:
                    f[r] = next_occupied(r, kap + 1)
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


def compiled_state(arr, m, f):
    offsets, cells, c_off, c_ray, c_kappa, ll = arr
    rays = cs.ray_state(f, ll)
    return cs.CellState(m, rays, cs.next_state(m, rays["f"], offsets, cells, ll), offsets, cells, c_off,
                        cs.pair_index(c_ray, c_kappa, ll), ll)  # fmt: skip


def orders(latent, rng):
    return {"systematic": latent, "permutation": np.ascontiguousarray(latent[rng.permutation(len(latent))]),
            "random": np.ascontiguousarray(latent[rng.integers(0, len(latent), len(latent))])}  # fmt: skip


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
    lp = None if lo is not None else local_of(model.prior)
    m0 = (rng.random(N * N) < (0.08 if start == "ogm-like" else 0.5)).astype(np.uint8)
    m0[model.known_free.numpy()] = 0
    f0 = first_hits(m0, offsets, cells)
    assert start == "ogm-like" or np.isinf(ll[np.arange(len(f0)), f0]).any()  # impossible readings present
    assert np.isinf(cs.pair_index(c_ray, c_kappa, ll)["ll"]).any()  # and impossible first hits
    for name, order in orders(latent, rng).items():
        m_plain, f_plain = m0.copy(), f0.copy()
        st = compiled_state(arr, m0.copy(), f0)
        for sweep in range(4):
            u = rng.random(len(order))
            if sweep == 3:
                u[::7] = 0.0  # the smallest uniforms: the exp-free shortcuts must not decide these
            a = plain_sweep(arr, m_plain, f_plain, order, u, update, prior_lo, lp)
            if lp is None:
                b = cs.sweep_independent(st, order, prior_lo, u, update)
            else:
                b = cs.sweep_local(st, order, lp, u, update)
            assert a == b, (name, sweep)
            assert np.array_equal(st.m, m_plain) and np.array_equal(st.rays["f"], f_plain), (name, sweep)
            np.testing.assert_array_equal(st.rays["ll_hit"], ll[np.arange(len(f_plain)), f_plain])
            known = st.nexts["s"] >= 0
            fresh = cs.next_state(st.m, st.rays["f"], offsets, cells, ll)
            assert np.array_equal(st.nexts[known], fresh[known]), (name, sweep)
        assert a > 0


def test_log_lik_ratio_matches_the_plain_sum_and_fills_the_cache():
    model = scene(IndependentPrior(0.3, N * N))
    arr = arrays(model, holes=0.03)
    offsets, cells, c_off, c_ray, c_kappa, ll = arr
    m = (np.random.default_rng(2).random(N * N) < 0.2).astype(np.uint8)
    m[model.known_free.numpy()] = 0
    f = first_hits(m, offsets, cells)
    st = compiled_state(arr, m, f)
    st.nexts["s"] = -1  # nothing known
    for k in range(N * N):
        d = 0.0
        for p in range(c_off[k], c_off[k + 1]):
            r, kap = c_ray[p], c_kappa[p]
            if f[r] < kap:
                continue
            nxt = kap + 1 + int(np.flatnonzero(np.r_[m[cells[offsets[r] + kap + 1:offsets[r + 1]]], 1])[0])
            t = float(ll[r, kap]) - float(ll[r, f[r] if f[r] > kap else nxt])
            if t == t:
                d += t
        got = cs.log_lik_ratio(st, k)
        assert got == d or (got != got and d != d), k
    first = np.unique(c_ray[f[c_ray] == c_kappa])  # rays whose first hit some cell is: now cached
    assert (st.nexts["s"][first] >= 0).all()


def test_new_value_shortcuts_are_exact():
    los = [-math.inf, -800.0, -745.2, -41.0, -40.0000001, -40.0, -39.99, -20.0, -1e-300, -0.0, 0.0, 1e-300, 20.0,
           39.99, 40.0, 40.0000001, 41.0, 800.0, math.inf, math.nan]  # fmt: skip
    us = [0.0, 5e-324, 1e-20, 4.2e-18, 4.25e-18, 4.2483542552915889e-18, 4.3e-18, 1e-17, 0.25, 0.5,
          0.9999999999999999]  # fmt: skip
    for update in (cs.HEAT_BATH, cs.METROPOLISED):
        for lo in los:
            for u in us:
                for cur in (0, 1):
                    assert cs.new_value(lo, u, cur, update) == plain_new_value(lo, u, cur, update), (update, lo, u, cur)
