r"""Compiled conditionals of the tiles kind (:class:`Tiles`).

``log p~(m) = sum_t log phi(key_t(m))`` over the tiles ``t`` of a fixed tiling of the plane by ``h x w``
rectangles; ``key_t`` packs the tile's *window* (the tile and a ring of ``pad`` border cells) into an
integer: bit ``i`` = window cell ``i``, the tile's own cells first (row-major), then the border ring
(row-major in the window). Window cells off the grid read as the tile's ``fill`` bits. ``phi`` is a sparse
table (sorted keys and their log values) per *segment*; a tile names its segment (e.g. the marginal table
of tiles cut by the grid edge). Keys missing from a segment fall back to segment ``fallback`` (keyed by the
tile's own bits only) when its border is unseen, else have ``phi = 0``. The patch tables of Section 5.2.2
(``pad = 0``) and the border-conditioned tables of Section 5.2.3 (``pad = 1``) are both of this kind.

For speed, tables over windows of at most 16 cells are also stored dense (one load per factor); sparse tables with
at most 16 border cells get a border index (:func:`~ogm_ppl.priors.compiled.tile_factors.border_index`: the run of
keys of each border in two loads, so a factor is a binary search among the few keys of its border and a tile's
candidates given its border are that run, :func:`~ogm_ppl.priors.compiled.tile_factors.border_range`); and a patch
update reads the keys of the tiles it touches once (:func:`~ogm_ppl.priors.compiled.tile_patches.tile_patch_setup`),
after which a candidate only ORs in its own bits and each touched tile's factor is memoised per the few bits the
patch sets in it (:func:`~ogm_ppl.priors.compiled.tile_patches.tile_patch_factors`). Patch updates whose patch is a
tile weigh only the configurations the tile's table allows given its border
(:func:`~ogm_ppl.priors.compiled.tile_patches.tile_candidates`, Section 5.2.2 / 5.2.3).

The bundle and its builder live here; its factor lookups in :mod:`~ogm_ppl.priors.compiled.tile_factors` and its
cell and patch conditionals in :mod:`~ogm_ppl.priors.compiled.tile_patches`, registered below.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ogm_ppl.priors.compiled.registry import register
from ogm_ppl.priors.compiled.scratch import MEMO_BITS
from ogm_ppl.priors.compiled.tile_factors import border_index, dense_factor_table, fallback_dense_table
from ogm_ppl.priors.compiled.tile_patches import (
    tile_candidate_weights,
    tile_candidates,
    tile_cell_log_odds,
    tile_escape,
    tile_of_anchor,
    tiles_patch_weights,
    touch_capacity,
)
from ogm_ppl.priors.compiled.transforms import check_beta, check_bias, scaled, shifted

__all__ = [
    "BORDER_INDEX_MAX_BITS",
    "BORDER_INDEX_MAX_ENTRIES",
    "DENSE_MAX_BITS",
    "DENSE_MAX_ENTRIES",
    "Tiles",
    "neighbour_layout",
    "tiles",
]

_I = np.zeros(0, np.int64)
_F = np.zeros(0, np.float64)
#: windows of at most this many cells get a dense factor table (at most DENSE_MAX_ENTRIES entries in all)
DENSE_MAX_BITS, DENSE_MAX_ENTRIES = 16, 1 << 20
#: borders of at most this many cells get a border index (at most BORDER_INDEX_MAX_ENTRIES entries in all)
BORDER_INDEX_MAX_BITS, BORDER_INDEX_MAX_ENTRIES = 16, 1 << 22
#: a neighbour layout is built for tiles of at most this many cells (its index is ``2^n_inner x nq``)
LAYOUT_MAX_INNER = 12


class Tiles(NamedTuple):
    r"""``log p~(m) = sum_t log phi(key_t(m))`` over the tiles ``t`` of a fixed tiling by ``h x w`` rectangles
    (Sections 5.2.2, 5.2.3; see :mod:`ogm_ppl.priors.compiled.tiles` for the keys, segments and fallback)."""

    rows: int
    cols: int
    w_dr: np.ndarray  # Lw int64: window offsets from the tile anchor (tile cells first)
    w_dc: np.ndarray
    n_inner: int  # cells of a tile (h * w)
    t_h: int
    t_w: int
    t_r0: int  # anchor (top-left cell) of tile (0, 0); <= 0
    t_c0: int
    t_rows: int  # tiles per column / row
    t_cols: int
    pad_r: int
    pad_c: int
    t_seg: np.ndarray  # T int64: segment of each tile
    t_fill: np.ndarray  # T int64: key bits of window cells off the grid
    seg_off: np.ndarray  # S + 1 int64
    keys: np.ndarray  # sorted within each segment
    logp: np.ndarray
    fallback: int  # segment used for unseen borders (-1: none, phi = 0)
    # the same factors as a dense table, for small windows: dense[s << dense_bits | key] = log phi(key) in
    # segment s (fallback resolved), so a lookup is one load instead of a binary search
    dense: np.ndarray  # S * 2^Lw float64 (empty: none)
    dense_bits: int  # Lw when ``dense`` is present, else -1
    # backed-off (strictly positive) tables: the segment of log lambda_b keyed by border (-1: none), and
    # the back-off table's cumulative sums over the 2^n_inner inner codes (the escape move's proposal)
    border_seg: int = -1
    back_cdf: np.ndarray = np.zeros(0, np.float64)
    # the keys of each border: segment s's keys with border code b (key >> n_inner) are
    # keys[b_start[s * (2^b_bits + 1) + b] : b_start[s * (2^b_bits + 1) + b + 1]] (empty, b_bits = -1: none)
    b_start: np.ndarray = np.zeros(0, np.int64)
    b_bits: int = -1
    # the neighbour layout of a tile update (:func:`~ogm_ppl.priors.compiled.tiles.neighbour_layout`): the
    # tiles whose windows hold cells of a tile away from the grid edge, in the order the generic update
    # visits them, as linear anchor offsets ``nb_lin`` (cells) and tile offsets ``nb_dt``; ``nb_pmask[q]``
    # the window bits of neighbour q that are the tile's cells; sub-configuration e of neighbour q
    # (``nb_eoff[q] <= e < nb_eoff[q + 1]``) sets the window bits ``nb_expand[e]``, and configuration w
    # of the tile reads entry ``nb_idx[w * nq + q]``; ``nb_box`` (rmin, rmax, cmin, cmax) the rows and
    # columns, from the anchor, that the neighbours' windows span (empty arrays: no layout)
    nb_lin: np.ndarray = np.zeros(0, np.int64)
    nb_dt: np.ndarray = np.zeros(0, np.int64)
    nb_pmask: np.ndarray = np.zeros(0, np.int64)
    nb_eoff: np.ndarray = np.zeros(0, np.int64)
    nb_expand: np.ndarray = np.zeros(0, np.int64)
    nb_idx: np.ndarray = np.zeros(0, np.int64)
    nb_box: np.ndarray = np.zeros(0, np.int64)
    # the window's linear cell offsets, ``w_dr * cols + w_dc`` (empty: not built)
    w_lin: np.ndarray = np.zeros(0, np.int64)
    # the fallback segment as a dense table over the inner codes (-inf where absent; empty: none)
    fb_dense: np.ndarray = np.zeros(0, np.float64)

    def sparse_patches(self) -> bool:
        return True

    def needs_escape(self) -> bool:
        """Whether a tile's patch update weighs only part of the configurations with mass (a backed-off
        table), so the sweep adds the escape move (and draws its uniforms)."""
        return self.border_seg >= 0

    def patch_capacity(self, L: int) -> int:
        seg = int(np.diff(self.seg_off).max()) if len(self.seg_off) > 1 else 0
        return max(1 << L if L <= 20 else 0, seg, 2)

    def tempered(self, beta: float) -> Tiles:
        """``beta log phi`` in every segment (the sparse values and the dense tables alike: the window table
        ``dense`` and the fallback's ``fb_dense``); missing keys (``phi = 0``) stay impossible, and the
        fallback reads the scaled values.

        Tempering (for parallel tempering, Geyer 1991): the bundle of ``p~(m)^beta``, every log-potential
        times ``beta``; ``-inf`` (a configuration the prior forbids) stays ``-inf``. ``beta = 1`` returns
        this very bundle; ``beta = 0`` gives the uniform distribution over the prior's support (the limit
        ``beta -> 0+``). Same type, so the compiled kernels sample the tempered prior unchanged.
        """
        b = check_beta(beta)
        if b == 1.0:
            return self
        return self._replace(logp=scaled(self.logp, b), dense=scaled(self.dense, b), fb_dense=scaled(self.fb_dense, b))

    def biased(self, bias: float) -> Tiles:
        """``log phi(key) + h * (occupied tile cells of key)`` in every segment but the border weights
        ``log lambda_b`` (keyed by border alone), and in the dense tables; the escape move's proposal
        ``back_cdf`` is kept (its Metropolis-Hastings ratio reads the biased factors). The tiles partition the
        grid, so the factors sum to ``h sum_k m_k`` plus a constant (:mod:`~ogm_ppl.priors.biased`)."""
        h = check_bias(bias)
        if h == 0.0:
            return self
        inner = self.keys & ((np.int64(1) << self.n_inner) - 1)
        occupied = np.zeros(self.keys.shape, dtype=np.float64)
        for b in range(int(self.n_inner)):  # popcount, bit by bit over the array (numpy < 2 has no bitwise_count)
            occupied += (inner >> b) & 1
        add = h * occupied
        if self.border_seg >= 0:
            add[self.seg_off[self.border_seg] : self.seg_off[self.border_seg + 1]] = 0.0
        out = self._replace(logp=shifted(self.logp, add))
        # the dense tables, rebuilt from the biased segments as the bundle's constructor builds them
        if self.fb_dense.size:
            out = out._replace(fb_dense=fallback_dense_table(out))
        if self.dense_bits >= 0:
            out = out._replace(dense=dense_factor_table(out._replace(dense=np.zeros(0), dense_bits=-1)))
        return out

    def tiles_patches(self, hw, anchors) -> bool:
        """Whether every patch (``h x w`` rectangles at ``anchors``, ``n x 2``) is a tile of this tiling."""
        if (self.t_h, self.t_w) != tuple(hw):
            return False
        a = np.asarray(anchors).reshape(-1, 2)
        return bool(((a[:, 0] - self.t_r0) % self.t_h == 0).all() and ((a[:, 1] - self.t_c0) % self.t_w == 0).all())

    def factor_extent(self) -> int:
        """The largest extent of a factor (cells): the span of a tile's window."""
        return int(max(np.ptp(self.w_dr), np.ptp(self.w_dc)))

    def window(self, grid_cols: int, r0: int, c0: int, rows: int, cols: int) -> Tiles:
        """Refused (``TypeError``): a table prior's tiling is anchored to the whole grid."""
        raise TypeError(
            "a table prior (patch table, border prior) cannot be restricted to a window: its tiling is anchored "
            "to the grid's origin; use ChromaticCellGibbs or PatchGibbs for it"
        )


def neighbour_layout(w_dr, w_dc, n_inner, tile, pad, cols, memo_bits=MEMO_BITS) -> dict:
    """The neighbour layout of a tile update away from the grid edge (the ``nb_*`` fields of
    :class:`Tiles`): the tiles other than ``t`` whose windows hold a cell of ``t``, listed in the order of
    :func:`~ogm_ppl.priors.compiled.tile_patches.tile_patch_setup` (by
    :func:`~ogm_ppl.priors.compiled.tile_patches.tiles_touching` of each tile cell in turn), each with the
    (tile bit, window bit) pairs through which the tile's configuration enters that neighbour's key.
    For a tile whose every cell is live and whose neighbours' windows lie on the grid, these depend on
    the tiling alone, so :func:`tile_candidate_weights` reads them instead of building them per update.
    Empty (no layout) for windows without a border, tiles of more than :data:`LAYOUT_MAX_INNER` cells or
    a neighbour sharing more than ``memo_bits`` cells."""
    h, w = int(tile[0]), int(tile[1])
    pr, pc = int(pad[0]), int(pad[1])
    empty = {k: np.zeros(0, np.int64) for k in ("nb_lin", "nb_dt", "nb_pmask", "nb_eoff", "nb_expand", "nb_idx")}
    empty["nb_box"] = np.zeros(0, np.int64)
    if (pr == 0 and pc == 0) or n_inner > LAYOUT_MAX_INNER:
        return empty
    w_dr = np.asarray(w_dr, np.int64)
    w_dc = np.asarray(w_dc, np.int64)
    # a virtual tiling with tile (t_i, t_j) far from any edge, anchored at (t_i h, t_j w)
    t_i, t_j = pr // h + 2, pc // w + 2
    ar, ac = t_i * h, t_j * w
    touched: list[tuple[int, int]] = []
    for i in range(n_inner):
        r, c = ar + int(w_dr[i]), ac + int(w_dc[i])
        for ti in range(max((r - pr) // h - 1, 0), (r + pr) // h + 1):
            a = ti * h
            if r < a - pr or r > a + h - 1 + pr:
                continue
            for tj in range(max((c - pc) // w - 1, 0), (c + pc) // w + 1):
                b = tj * w
                if c < b - pc or c > b + w - 1 + pc:
                    continue
                if (ti, tj) not in touched:
                    touched.append((ti, tj))
    nb = [(ti - t_i, tj - t_j) for ti, tj in touched if (ti, tj) != (t_i, t_j)]
    lin, dt, pmask, eoff, expand = [], [], [], [0], []
    sub_pairs = []
    rmin = cmin = 1 << 30
    rmax = cmax = -(1 << 30)
    for di, dj in nb:
        pairs = []  # (tile bit, window bit) in window-bit order
        for x in range(len(w_dr)):
            rr, cc = di * h + int(w_dr[x]), dj * w + int(w_dc[x])
            rmin, rmax, cmin, cmax = min(rmin, rr), max(rmax, rr), min(cmin, cc), max(cmax, cc)
            if 0 <= rr < h and 0 <= cc < w:
                pairs.append((rr * w + cc, x))
        if len(pairs) > memo_bits:
            return empty
        lin.append(di * h * int(cols) + dj * w)
        dt.append((di, dj))
        pmask.append(sum(1 << x for _, x in pairs))
        for sub in range(1 << len(pairs)):
            expand.append(sum(1 << x for p, (_, x) in enumerate(pairs) if (sub >> p) & 1))
        eoff.append(len(expand))
        sub_pairs.append(pairs)
    nq = len(nb)
    idx = np.empty((1 << n_inner, nq), np.int64)
    codes = np.arange(1 << n_inner, dtype=np.int64)
    for q, pairs in enumerate(sub_pairs):
        sub_code = np.zeros(1 << n_inner, np.int64)
        for p, (b, _) in enumerate(pairs):
            sub_code |= ((codes >> b) & 1) << p
        idx[:, q] = eoff[q] + sub_code
    return {
        "nb_lin": np.asarray(lin, np.int64),
        "nb_dt": np.asarray(dt, np.int64).reshape(-1),  # (di, dj) of each neighbour, flat
        "nb_pmask": np.asarray(pmask, np.int64),
        "nb_eoff": np.asarray(eoff, np.int64),
        "nb_expand": np.asarray(expand, np.int64),
        "nb_idx": np.ascontiguousarray(idx.ravel()),
        "nb_box": np.asarray([rmin, rmax, cmin, cmax], np.int64),
    }


def tiles(
    rows,
    cols,
    geometry,
    n_inner,
    tile,
    pad,
    t_seg,
    t_fill,
    seg_keys,
    seg_logp,
    fallback=-1,
    border_seg=-1,
    back_cdf=None,
) -> Tiles:
    """A :class:`Tiles` bundle from a tiling (``geometry``: :func:`~ogm_ppl.priors.local.tiling`) and
    per-segment (keys, log-values) lists; windows of at most :data:`DENSE_MAX_BITS` cells also get the
    dense table. A backed-off table (:class:`~ogm_ppl.priors.backoff.BackoffBorderPrior`) names its
    border-weight segment ``border_seg`` (keys: border codes, values ``log lambda_b``), followed by the
    segment of ``log back`` over every inner code in order, and passes the back-off table's cumulative
    sums ``back_cdf`` (``2^n_inner``, last entry 1); its ``fallback`` segment is then only the candidate
    set of a tile whose border was never seen."""
    if border_seg >= 0:
        fk = np.asarray(seg_keys[border_seg + 1])
        if not np.array_equal(fk, np.arange(1 << int(n_inner))):
            raise ValueError("a backed-off table's back-off segment must hold every inner code in order")
        cdf = np.asarray(back_cdf, np.float64)
        if cdf.shape != (1 << int(n_inner),) or (np.diff(cdf) < 0).any() or cdf[-1] != 1.0:
            raise ValueError("back_cdf must be the non-decreasing cumulative sums of 2^n_inner entries, ending at 1")
    w_dr, w_dc, r0, c0, t_rows, t_cols, _ = geometry
    seg_off = np.zeros(len(seg_keys) + 1, np.int64)
    keys, logp = [], []
    for s, (k, lp) in enumerate(zip(seg_keys, seg_logp)):
        order = np.argsort(k, kind="stable")
        keys.append(np.asarray(k, np.int64)[order])
        logp.append(np.asarray(lp, np.float64)[order])
        seg_off[s + 1] = seg_off[s] + len(k)
    bundle = Tiles(
        rows=int(rows),
        cols=int(cols),
        w_dr=w_dr,
        w_dc=w_dc,
        n_inner=int(n_inner),
        t_h=int(tile[0]),
        t_w=int(tile[1]),
        t_r0=int(r0),
        t_c0=int(c0),
        t_rows=int(t_rows),
        t_cols=int(t_cols),
        pad_r=int(pad[0]),
        pad_c=int(pad[1]),
        t_seg=np.ascontiguousarray(t_seg, np.int64),
        t_fill=np.ascontiguousarray(t_fill, np.int64),
        seg_off=seg_off,
        keys=np.ascontiguousarray(np.concatenate(keys) if keys else _I, np.int64),
        logp=np.ascontiguousarray(np.concatenate(logp) if logp else _F, np.float64),
        fallback=int(fallback),
        dense=_F,
        dense_bits=-1,
        border_seg=int(border_seg),
        back_cdf=np.ascontiguousarray(back_cdf if border_seg >= 0 else _F, np.float64),
    )
    bundle = bundle._replace(
        w_lin=np.ascontiguousarray(np.asarray(w_dr, np.int64) * int(cols) + np.asarray(w_dc, np.int64)),
        **neighbour_layout(w_dr, w_dc, int(n_inner), tile, pad, int(cols)),
    )
    if bundle.fallback >= 0 and int(n_inner) <= DENSE_MAX_BITS:
        bundle = bundle._replace(fb_dense=fallback_dense_table(bundle))
    Lw = len(w_dr)
    B = Lw - int(n_inner)
    if B <= BORDER_INDEX_MAX_BITS and (len(seg_keys) << B) <= BORDER_INDEX_MAX_ENTRIES:
        bundle = bundle._replace(b_start=border_index(bundle.keys, seg_off, int(n_inner), B), b_bits=B)
    if Lw <= DENSE_MAX_BITS and (len(seg_keys) << Lw) <= DENSE_MAX_ENTRIES:
        bundle = bundle._replace(dense=dense_factor_table(bundle), dense_bits=Lw)
    return bundle


def _cell(prior, k, m):
    return tile_cell_log_odds(prior, k, m)


def _patch(prior, patch, m, cands, n, out, ts):
    tiles_patch_weights(prior, patch, m, cands, n, out, ts)


def _cands(prior, r0, c0, h, w, patch, n_live, pinned, m, cands, cand_lp):
    t = tile_of_anchor(prior, r0, c0, h, w)
    if t >= 0:
        return np.int64(tile_candidates(prior, t, patch, pinned, m, cands, cand_lp)), t
    if n_live > 62 or (np.int64(1) << n_live) > cands.shape[0]:
        return np.int64(-1), t
    W = np.int64(1) << n_live
    for j in range(W):
        cands[j] = j
    return W, t


def _weights(prior, patch, m, cands, n, tag, cand_lp, out, ts):
    tile_candidate_weights(prior, patch, m, cands, n, tag, cand_lp, out, ts)


def _capacity(prior, L):
    return touch_capacity(prior, L)


def _restricted(prior, tag):
    return tag >= 0 and prior.border_seg >= 0


def _escape(prior, tag, patch, m, u, pair_lp):
    return tile_escape(prior, tag, patch, m, u, pair_lp)


def _shared(prior):
    # windows without a border (pad = 0): a full tile's candidates and weights are its segment's
    return prior.seg_off.shape[0] - 1 if prior.pad_r == 0 and prior.pad_c == 0 else 0


def _shared_key(prior, r0, c0, h, w, n_live):
    if n_live != prior.n_inner or prior.pad_r != 0 or prior.pad_c != 0 or prior.border_seg >= 0:
        return np.int64(-1)
    t = tile_of_anchor(prior, r0, c0, h, w)
    return np.int64(-1) if t < 0 else np.int64(prior.t_seg[t])


register(
    Tiles,
    cell_log_odds=_cell,
    patch_prior_weights=_patch,
    patch_candidates=_cands,
    candidate_weights=_weights,
    scratch_capacity=_capacity,
    restricted=_restricted,
    escape_proposal=_escape,
    shared_weights=_shared,
    shared_weights_key=_shared_key,
    patch_allocates=False,
)
