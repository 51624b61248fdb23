r"""The data-driven patch prior of Section 5.2.2: a table over the configurations of a patch shape.

Code convention (shared with the table learner): a window's cells in row-major order, bit ``i`` = cell
``i``, ``code = sum_i m_i << i`` (little-endian). Zeros are allowed: configurations never seen have no
mass, and patch Gibbs enumerates only the configurations in the table (Algorithm 2, Table 5.1).

**The prior over a whole map.** The thesis treats each patch as independent of the rest of the map,
``p(a_k = w | m_{-a_k}) = p(a_k = w)`` (Section 5.2.2). The distribution over maps for which this holds
exactly is a *tiling*: the plane is cut into ``h x w`` tiles (one of which starts at ``origin``), and

.. math:: p(m) = \prod_{t} p_t(m_t),

where ``p_t`` is the table for a tile inside the grid and, for a tile cut by the grid edge, the table's
marginal over the cells that fall off the grid. This ``log_prob`` is exactly normalised. Patch Gibbs with
patches aligned to the tiling (the default systematic scan, ``offset = origin``) then samples each tile
from ``p(w) p(z | w, rest)`` over the table's support alone; updates that straddle tiles (single cells,
random placements) are exact as well, through the product of the tables they touch.
"""

from __future__ import annotations

import numpy as np
import torch

from ogm_ppl.priors.compiled import tiles
from ogm_ppl.priors.local import LocalMapPrior, grid_shape, table_occupancy, tiles_log_prob, tiling

__all__ = ["PatchTablePrior", "truncate_mass"]


def _patch_hw(patch, ndim: int) -> tuple[int, int]:
    hw: tuple[int, ...]
    if np.isscalar(patch):
        hw = (1, int(patch))  # type: ignore[arg-type]  # numpy's isscalar TypeGuard narrows to generic | complex | bytes
    else:
        hw = tuple(int(v) for v in patch)
        if len(hw) == 1:
            hw = (1, hw[0])
    if len(hw) != 2 or hw[0] < 1 or hw[1] < 1:
        raise ValueError(f"patch must be an int L (a run) or (h, w), got {patch!r}")
    if ndim == 1 and hw[0] != 1:
        raise ValueError("a 1D grid takes runs (1, L) only")
    return hw[0], hw[1]


def _table(codes, weights, nbits: int) -> tuple[np.ndarray, np.ndarray]:
    """Validated, de-duplicated (codes, probabilities) with zeros dropped."""
    codes = np.asarray(codes).astype(np.int64).ravel()
    w = np.asarray(weights, dtype=np.float64).ravel()
    if codes.shape != w.shape:
        raise ValueError(f"codes ({codes.size}) and counts ({w.size}) differ in length")
    if codes.size == 0:
        raise ValueError("the table is empty")
    if (codes < 0).any() or (codes >= (np.int64(1) << nbits)).any():
        raise ValueError(f"codes must lie in 0..2^{nbits} - 1")
    if not np.isfinite(w).all() or (w < 0).any():
        raise ValueError("counts / probabilities must be finite and non-negative")
    u, inv = np.unique(codes, return_inverse=True)
    tot = np.bincount(inv, weights=w)
    keep = tot > 0
    if not keep.any():
        raise ValueError("the table has no mass")
    return u[keep], tot[keep] / tot[keep].sum()


def truncate_mass(codes, probs, mass: float):
    """The most likely configurations carrying at least ``mass`` of the probability, renormalised
    (Table 5.1's "most likely" rows: 99.9%)."""
    if not 0.0 < mass <= 1.0:
        raise ValueError(f"mass must lie in (0, 1], got {mass}")
    order = np.argsort(-probs, kind="stable")
    c = np.cumsum(probs[order])
    n = int(np.searchsorted(c, mass * c[-1] * (1 - 1e-12))) + 1
    keep = np.sort(order[: min(n, len(order))])
    return codes[keep], probs[keep] / probs[keep].sum()


class PatchTablePrior(LocalMapPrior):
    """Independent tiles, each drawn from a table over its ``h x w`` configurations (Section 5.2.2).

    Args:
        shape: grid shape ``(K,)`` or ``(rows, cols)``.
        codes: window codes (bit ``i`` = cell ``i`` of the patch in row-major order).
        counts: counts or probabilities of the codes (normalised here; zeros allowed).
        patch: ``L`` (a 1D run) or ``(h, w)`` (``(3, 3)``, ``(5, 5)``).
        mass: keep only the most likely configurations carrying this much mass (e.g. ``0.999``).
        origin: ``(row, col)`` where one tile starts (1D: an int column).

    >>> p = PatchTablePrior((4,), codes=[0, 3], counts=[3, 1], patch=2)
    >>> round(float(p.log_prob(torch.tensor([0., 0., 1., 1.])).exp()), 4)  # 3/4 * 1/4
    0.1875
    """

    normalised = True

    def __init__(self, shape, codes, counts, patch=(3, 3), mass: float | None = None, origin=(0, 0)) -> None:
        self.rows, self.cols, self.ndim = grid_shape(shape)
        self.num_cells = self.rows * self.cols
        self.patch = _patch_hw(patch, self.ndim)
        h, w = self.patch
        L = h * w
        if L > 48:
            raise ValueError(f"patches of {L} cells exceed the 48-bit codes")
        c, p = _table(codes, counts, L)
        if mass is not None:
            c, p = truncate_mass(c, p, float(mass))
        self.codes, self.probs = c, p
        self.can_be_zero = len(c) < 2**L  # a configuration the table never counted has mass 0
        origin = (0, int(origin)) if np.isscalar(origin) else tuple(int(o) for o in origin)  # type: ignore[arg-type]  # numpy's isscalar TypeGuard narrows to generic | complex | bytes
        self.origin = origin
        geo = tiling(self.rows, self.cols, self.patch, (0, 0), origin)
        off_mask = geo[6]
        masks, t_seg = np.unique(off_mask, return_inverse=True)
        seg_keys, seg_logp = [], []
        for mk in masks:
            keys, inv = np.unique(c & ~mk, return_inverse=True)
            with np.errstate(divide="ignore"):
                seg_logp.append(np.log(np.bincount(inv, weights=p)))
            seg_keys.append(keys)
        self._masks = masks
        self._compiled = tiles(
            self.rows, self.cols, geo, L, self.patch, (0, 0), t_seg, np.zeros(len(t_seg), np.int64), seg_keys, seg_logp
        )
        self.mean_occupancy = table_occupancy(c, p, L)

    def __repr__(self) -> str:
        return f"PatchTablePrior(patch={self.patch}, configurations={len(self.codes)}, cells={self.num_cells})"

    @property
    def num_configurations(self) -> int:
        return len(self.codes)

    def log_prob(self, maps):
        """``sum_t log p_t(m_t)``: exact (normalised) ``log p(m)``, ``... x K -> ...``."""
        return tiles_log_prob(self, maps)

    def sample(self, sample_shape=(), generator=None):
        """Exact draws: every tile from its (marginal) table, independently."""
        shape = torch.Size(sample_shape)
        B = int(np.prod(shape)) if len(shape) else 1
        lp = self._compiled
        maps = np.zeros((B, self.num_cells), np.float64)
        T = lp.t_rows * lp.t_cols
        ti, tj = np.divmod(np.arange(T), lp.t_cols)
        ar, ac = lp.t_r0 + ti * lp.t_h, lp.t_c0 + tj * lp.t_w
        for s in range(len(lp.seg_off) - 1):
            tiles = np.flatnonzero(lp.t_seg == s)
            a, b = lp.seg_off[s], lp.seg_off[s + 1]
            probs = torch.from_numpy(np.exp(lp.logp[a:b]))
            pick = torch.multinomial(probs, B * len(tiles), replacement=True, generator=generator).numpy()
            keys = lp.keys[a:b][pick].reshape(B, len(tiles))
            for i in range(lp.n_inner):
                r = ar[tiles] + lp.w_dr[i]
                c = ac[tiles] + lp.w_dc[i]
                ok = (r >= 0) & (r < self.rows) & (c >= 0) & (c < self.cols)
                maps[:, (r * self.cols + c)[ok]] = (keys[:, ok] >> i) & 1
        return torch.from_numpy(maps).reshape(*shape, self.num_cells)
