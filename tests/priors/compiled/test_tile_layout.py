"""The neighbour layout of tile updates (:func:`neighbour_layout`, :func:`tile_neighbour_factors`): on every
tile where it applies, the candidates' weights equal those of the generic update (:func:`tile_patch_setup`
+ :func:`tile_patch_factors`) bit for bit; and :func:`tile_key` equals a direct reading of the window."""

from __future__ import annotations

import numba as nb
import numpy as np
import pytest

from ogm_ppl.priors import BorderPatchPrior
from ogm_ppl.priors.backoff import BackoffBorderPrior
from ogm_ppl.priors.compiled.scratch import tile_scratch, tile_scratch_on
from ogm_ppl.priors.compiled.tile_factors import tile_key
from ogm_ppl.priors.compiled.tile_patches import (
    _layout_applies,
    tile_neighbour_factors,
    tile_patch_factors,
    tile_patch_setup,
    touch_capacity,
)

SHAPE = (23, 26)  # not a multiple of the tile: the edge tiles are cut, and the layout must not apply there


def _window_codes(maps, inner):
    """(border, inner) codes of every h x w window with its one-cell ring inside each ``rows x cols`` map
    (bit order of :func:`~ogm_ppl.priors.local.tiling`: inner cells row-major, then the ring row-major)."""
    h, w = inner
    ring = [(r, c) for r in range(-1, h + 1) for c in range(-1, w + 1) if not (0 <= r < h and 0 <= c < w)]
    inn = [(r, c) for r in range(h) for c in range(w)]
    b_all, i_all = [], []
    for g in maps:
        R, C = g.shape
        rr, cc = np.meshgrid(np.arange(1, R - h), np.arange(1, C - w), indexing="ij")
        rr, cc = rr.ravel(), cc.ravel()
        i_all.append(sum(g[rr + r, cc + c].astype(np.int64) << k for k, (r, c) in enumerate(inn)))
        b_all.append(sum(g[rr + r, cc + c].astype(np.int64) << k for k, (r, c) in enumerate(ring)))
    return np.concatenate(b_all), np.concatenate(i_all)


def _maps(seed, density):
    rng = np.random.default_rng(seed)
    return [(rng.random(SHAPE) < density).astype(np.uint8) for _ in range(3)]


def _border(inner, maps, unseen="marginal", origin=(0, 0)):
    b, i = _window_codes(maps, inner)
    return BorderPatchPrior(SHAPE, b, i, np.ones(len(b)), inner=inner, unseen=unseen, origin=origin)


def _backoff(inner, maps):
    b, i = _window_codes(maps, inner)
    back = np.random.default_rng(0).random(1 << (inner[0] * inner[1])) + 0.1
    return BackoffBorderPrior(SHAPE, b, i, np.ones(len(b)), kappa=0.7, back=back, inner=inner, origin=(1, 2))


@nb.njit(cache=False)
def _compare(lp, m, cands, cand_lp, fast_out, slow_out, applies):
    """For every tile: whether the layout applies and, where it does, both updates' weights."""
    T = lp.t_rows * lp.t_cols
    Li = lp.n_inner
    ts = tile_scratch(m.shape[0], touch_capacity(lp, Li))
    patch = np.empty(Li, np.int64)
    n = cands.shape[0]
    for t in range(T):
        ti = t // lp.t_cols
        ar = lp.t_r0 + ti * lp.t_h
        ac = lp.t_c0 + (t - ti * lp.t_cols) * lp.t_w
        for i in range(Li):
            r = ar + lp.w_dr[i]
            c = ac + lp.w_dc[i]
            patch[i] = r * lp.cols + c if (0 <= r < lp.rows and 0 <= c < lp.cols) else -1
        applies[t] = _layout_applies(lp, t, patch)
        if not applies[t]:
            continue
        for j in range(n):
            fast_out[t, j] = cand_lp[j]
            slow_out[t, j] = cand_lp[j]
        tile_neighbour_factors(lp, t, m, cands, n, fast_out[t], ts.memo)
        ts2 = tile_scratch_on(ts.bit_of, touch_capacity(lp, Li))
        nt = tile_patch_setup(lp, patch, m, t, ts2)
        tile_patch_factors(lp, nt, ts2, cands, n, slow_out[t])


@pytest.mark.parametrize(
    "make",
    [
        lambda maps: _border((3, 3), maps),
        lambda maps: _border((3, 3), maps, unseen="zero", origin=(2, 1)),
        lambda maps: _border((2, 2), maps),  # 16-cell windows: the dense table
        lambda maps: _border((2, 3), maps),
        lambda maps: _backoff((3, 3), maps),
    ],
)
@pytest.mark.parametrize("density", [0.1, 0.5, 0.9])
def test_the_layout_gives_the_generic_weights_bit_for_bit(make, density):
    maps = _maps(int(density * 10), density)  # the map of the test among those the table counted
    lp = make(maps).compiled()
    assert lp.nb_lin.shape[0] == 8  # a one-cell ring: the 8 neighbouring tiles
    rng = np.random.default_rng(7)
    m = np.ascontiguousarray(maps[0].ravel())
    W = 1 << lp.n_inner
    cands = np.arange(W, dtype=np.int64)
    cand_lp = np.where(rng.random(W) < 0.2, -np.inf, rng.normal(size=W))
    T = lp.t_rows * lp.t_cols
    fast = np.full((T, W), np.nan)
    slow = np.full((T, W), np.nan)
    applies = np.zeros(T, np.bool_)
    _compare(lp, m, cands, cand_lp, fast, slow, applies)
    assert 0 < applies.sum() < T  # interior tiles use it, the tiles at the grid's edge do not
    np.testing.assert_array_equal(fast[applies], slow[applies])
    assert np.isfinite(fast[applies]).any() and np.isneginf(fast[applies]).any()


def test_tile_key_reads_the_window_with_off_grid_cells_as_the_fill():
    lp = _border((3, 3), _maps(5, 0.4), origin=(1, 2)).compiled()
    rng = np.random.default_rng(6)
    m = (rng.random(SHAPE[0] * SHAPE[1]) < 0.4).astype(np.uint8)
    key_of = nb.njit(lambda lp, t, m: tile_key(lp, t, m))
    for t in range(lp.t_rows * lp.t_cols):
        ti, tj = divmod(t, lp.t_cols)
        ar, ac = lp.t_r0 + ti * lp.t_h, lp.t_c0 + tj * lp.t_w
        want = int(lp.t_fill[t])
        for i, (dr, dc) in enumerate(zip(lp.w_dr, lp.w_dc)):
            r, c = ar + dr, ac + dc
            if 0 <= r < lp.rows and 0 <= c < lp.cols and m[r * lp.cols + c]:
                want |= 1 << i
        assert key_of(lp, t, m) == want, t
