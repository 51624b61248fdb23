"""The bundles of arrays a prior hands to the compiled kernels (:meth:`MapPrior.compiled`), one per kind.

Each bundle is a ``typing.NamedTuple`` built by keyword (numba takes it as one argument and compiles one
specialisation of a kernel per bundle type). Its kind's compiled conditionals are registered beside it
(:func:`~ogm_ppl.priors.compiled.registry.register`); the kernels never look at which kind they hold.
The Python methods (``sparse_patches``, ``patch_capacity``, ``tiles_patches``) tell a kernel's set-up how many candidate
configurations a patch update may weigh and whether patches larger than 20 cells are possible.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

__all__ = ["CompiledPrior", "IndependentCells", "PatternField", "Stencil", "Tiles"]


def _check_beta(beta) -> float:
    """``beta`` as a float, checked: finite and ``>= 0``."""
    b = float(beta)
    if not (np.isfinite(b) and b >= 0.0):
        raise ValueError(f"a tempering exponent beta must be finite and >= 0, got {beta!r}")
    return b


def _check_bias(bias) -> float:
    """``bias`` as a float, checked: finite."""
    h = float(bias)
    if not np.isfinite(h):
        raise ValueError(f"a bias must be finite, got {bias!r}")
    return h


def _shifted(x: np.ndarray, add) -> np.ndarray:
    """``x + add`` for the finite entries of ``x``; infinite entries stay as they are."""
    return np.where(np.isfinite(x), x + add, x)


def _scaled(x: np.ndarray, beta: float) -> np.ndarray:
    """``beta * x`` for the finite entries of ``x``; infinite entries (``log 0 = -inf``, hard constraints)
    stay as they are, so ``beta = 0`` gives ``0`` on the support and keeps ``-inf`` off it."""
    out = np.array(x, dtype=np.float64, order="C")  # a copy
    finite = np.isfinite(out)
    out[finite] *= beta
    return out


class IndependentCells(NamedTuple):
    """Cells independent a priori: ``log p(m) = sum_k m_k l_k + const``."""

    log_odds: np.ndarray  # K float64: l_k = log lambda_k - log(1 - lambda_k)

    def sparse_patches(self) -> bool:
        """Whether patch updates may weigh a sparse support (so patches may exceed 20 cells)."""
        return False

    def patch_capacity(self, L: int) -> int:
        return max(1 << L if L <= 20 else 0, 2)

    def tempered(self, beta: float) -> IndependentCells:
        """``log p~(m)^beta = beta sum_k m_k l_k``: log-odds ``beta l_k`` (``+-inf`` kept).

        Tempering (for parallel tempering, Geyer 1991): the bundle of ``p~(m)^beta``, every log-potential
        times ``beta``; ``-inf`` (a configuration the prior forbids) stays ``-inf``. ``beta = 1`` returns
        this very bundle; ``beta = 0`` gives the uniform distribution over the prior's support (the limit
        ``beta -> 0+``). Same type, so the compiled kernels sample the tempered prior unchanged.
        """
        b = _check_beta(beta)
        return self if b == 1.0 else self._replace(log_odds=_scaled(self.log_odds, b))

    def biased(self, bias: float) -> IndependentCells:
        """``log p~(m) + h sum_k m_k``: log-odds ``l_k + h`` (``+-inf`` kept; :mod:`~ogm_ppl.priors.biased`)."""
        h = _check_bias(bias)
        return self if h == 0.0 else self._replace(log_odds=_shifted(self.log_odds, h))

    def tiles_patches(self, hw, anchors) -> bool:
        return False


class Stencil(NamedTuple):
    r"""A pairwise binary field on a stencil of offsets ``d`` (Section 5.2.1):
    ``l(m_k | m_-k) = h_k + sum_{d: k+d in G} (a_d + J_d m_{k+d})`` with ``J_d = J_{-d}``."""

    rows: int
    cols: int
    unary: np.ndarray  # K float64: h_k
    dr: np.ndarray  # D int64: the offsets
    dc: np.ndarray  # D int64
    bias: np.ndarray  # D float64: a_d
    coupling: np.ndarray  # D float64: J_d

    def sparse_patches(self) -> bool:
        return False

    def patch_capacity(self, L: int) -> int:
        return max(1 << L if L <= 20 else 0, 2)

    def tempered(self, beta: float) -> Stencil:
        """``beta h_k``, ``beta a_d``, ``beta J_d``: the conditional log-odds scale by ``beta``.

        Tempering (for parallel tempering, Geyer 1991): the bundle of ``p~(m)^beta``, every log-potential
        times ``beta``; ``-inf`` (a configuration the prior forbids) stays ``-inf``. ``beta = 1`` returns
        this very bundle; ``beta = 0`` gives the uniform distribution over the prior's support (the limit
        ``beta -> 0+``). Same type, so the compiled kernels sample the tempered prior unchanged.
        """
        b = _check_beta(beta)
        if b == 1.0:
            return self
        return self._replace(
            unary=_scaled(self.unary, b), bias=_scaled(self.bias, b), coupling=_scaled(self.coupling, b)
        )

    def biased(self, bias: float) -> Stencil:
        """``log p~(m) + h sum_k m_k``: unary terms ``h_k + h`` (:mod:`~ogm_ppl.priors.biased`)."""
        h = _check_bias(bias)
        return self if h == 0.0 else self._replace(unary=_shifted(self.unary, h))

    def tiles_patches(self, hw, anchors) -> bool:
        return False


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
        b = _check_beta(beta)
        if b == 1.0:
            return self
        return self._replace(
            logp=_scaled(self.logp, b), dense=_scaled(self.dense, b), fb_dense=_scaled(self.fb_dense, b)
        )

    def biased(self, bias: float) -> Tiles:
        """``log phi(key) + h * (occupied tile cells of key)`` in every segment but the border weights
        ``log lambda_b`` (keyed by border alone), and in the dense tables; the escape move's proposal
        ``back_cdf`` is kept (its Metropolis-Hastings ratio reads the biased factors). The tiles partition the
        grid, so the factors sum to ``h sum_k m_k`` plus a constant (:mod:`~ogm_ppl.priors.biased`)."""
        h = _check_bias(bias)
        if h == 0.0:
            return self
        inner = self.keys & ((np.int64(1) << self.n_inner) - 1)
        occupied = np.zeros(self.keys.shape, dtype=np.float64)
        for b in range(int(self.n_inner)):  # popcount, bit by bit over the array (numpy < 2 has no bitwise_count)
            occupied += (inner >> b) & 1
        add = h * occupied
        if self.border_seg >= 0:
            add[self.seg_off[self.border_seg] : self.seg_off[self.border_seg + 1]] = 0.0
        out = self._replace(logp=_shifted(self.logp, add))
        # the dense tables, rebuilt from the biased segments as the bundle's constructor builds them
        from ogm_ppl.priors.compiled.tiles import dense_factor_table, fallback_dense_table

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


class PatternField(NamedTuple):
    r"""A translation-invariant field of ``w x w`` patterns, optionally at two scales:
    ``log p~(m) = sum_windows theta[code] + sum_pooled windows theta2[code]`` (see
    :mod:`~ogm_ppl.priors.compiled.field` for the codes and the pooled grid)."""

    rows: int
    cols: int
    w: int  # window side
    n_scales: int  # 1 or 2
    prow: int  # pooled grid: ceil(rows / 2) x ceil(cols / 2)
    pcol: int
    theta: np.ndarray  # 2^(w w) float64: log-potential of each window code at scale 1
    theta2: np.ndarray  # 2^(w w) float64: the same at scale 2 (zeros when n_scales == 1)
    # w = 3: delta[a << 15 | block] = the log-odds terms of the three windows anchored on row a of a cell's
    # 5 x 5 neighbourhood, block = its rows a .. a + 2 (field._delta_table); three loads a cell; else empty
    delta: np.ndarray
    delta2: np.ndarray

    def sparse_patches(self) -> bool:
        return False

    def patch_capacity(self, L: int) -> int:
        return max(1 << L if L <= 20 else 0, 2)

    def tiles_patches(self, hw, anchors) -> bool:
        return False

    def tempered(self, beta: float) -> PatternField:
        """The bundle of ``beta * log p~`` (every log-potential times ``beta``)."""
        b = float(beta)
        return self._replace(theta=self.theta * b, theta2=self.theta2 * b, delta=self.delta * b, delta2=self.delta2 * b)


#: any bundle a prior's ``compiled()`` may return (a new kind adds its class here and registers itself)
CompiledPrior = IndependentCells | Stencil | Tiles | PatternField
