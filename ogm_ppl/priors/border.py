r"""The border-conditioned data-driven prior of Section 5.2.3: ``p(patch | its border)``.

A table of counts of (border, inner) configurations: e.g. a 3 x 3 patch given its 16 border cells (the
ring of its 5 x 5 window) or one cell given its 8 neighbours. Codes follow the learner's convention: inner
cells row-major, bit ``i`` = inner cell ``i``; border cells in row-major order of the window (the ring),
bit ``j`` = border cell ``j``. Stored sparsely: the keys ``border << L_inner | inner`` sorted, i.e. sorted
border codes with, per border, the allowed inner codes and their log-probabilities (a CSR).

**The prior over a whole map.** The thesis samples each patch from ``p(a_k | border_{a_k})`` as if this
were the patch's full conditional (Section 5.2.3). A set of such conditionals is in general not the
conditional of any joint distribution. To stay exact we define the joint they suggest on a tiling of the
plane by patches,

.. math:: p(m) = \frac{1}{Z} \prod_t p(\text{inner}_t \mid \text{border}_t),

(cells off the grid read as ``outside``, occupied by default like the thesis's walled maps), and sample
*its* posterior: the conditional of tile ``t`` is ``p(inner_t | border_t)`` times the factors of the
neighbouring tiles whose borders hold cells of ``t``. The support is still that of
``p(. | border_t)`` (usually one to a few configurations, Fig. 5.14b), so a 3 x 3 update costs a handful
of configurations (Table 5.1). ``log_prob`` is exact up to ``log Z``. Borders never seen in the data
fall back (``unseen="marginal"``) to the inner table summed over all borders, so no map is ruled out
merely for an unseen border; ``unseen="zero"`` gives them no mass.
"""

from __future__ import annotations

import numpy as np

from ogm_ppl.priors.compiled import tiles
from ogm_ppl.priors.local import LocalMapPrior, grid_shape, table_occupancy, tiles_log_prob, tiling
from ogm_ppl.priors.patch_table import _patch_hw

__all__ = ["BorderPatchPrior"]


class BorderPatchPrior(LocalMapPrior):
    """``p(inner | border)`` tables on a tiling by inner patches (Section 5.2.3).

    Args:
        shape: grid shape ``(K,)`` or ``(rows, cols)``.
        border_codes, inner_codes, counts: one entry per observed (border, inner) pair.
        inner: the inner patch, ``(3, 3)``, ``(1, 1)`` (one cell given its 8 neighbours), or ``L`` (1D run
            with its 2 border cells).
        outside: value of cells off the grid (1: occupied, as maps with a walled border; 0: free).
        unseen: ``"marginal"`` (default) or ``"zero"``, see the module docstring.
        origin: ``(row, col)`` where one tile starts.

    >>> p = BorderPatchPrior((3,), border_codes=[0, 3, 1, 2], inner_codes=[0, 1, 1, 1], counts=[9, 9, 1, 1], inner=1)
    >>> p.num_borders, p.max_per_border
    (4, 1)
    """

    normalised = False
    can_be_zero = True  # a (border, inner) pair never counted has mass 0

    def __init__(
        self,
        shape,
        border_codes,
        inner_codes,
        counts,
        inner=(3, 3),
        outside: int = 1,
        unseen: str = "marginal",
        origin=(0, 0),
    ) -> None:
        self.rows, self.cols, self.ndim = grid_shape(shape)
        self.num_cells = self.rows * self.cols
        self.inner = _patch_hw(inner, self.ndim)
        if outside not in (0, 1):
            raise ValueError(f"outside must be 0 or 1, got {outside!r}")
        if unseen not in ("marginal", "zero"):
            raise ValueError(f"unseen must be 'marginal' or 'zero', got {unseen!r}")
        h, w = self.inner
        Li = h * w
        pad = (0, 1) if self.ndim == 1 else (1, 1)
        Lb = (h + 2 * pad[0]) * (w + 2 * pad[1]) - Li
        if Li + Lb > 62:
            raise ValueError(f"windows of {Li + Lb} cells exceed 62-bit keys")
        b = np.asarray(border_codes).astype(np.int64).ravel()
        i = np.asarray(inner_codes).astype(np.int64).ravel()
        c = np.asarray(counts, dtype=np.float64).ravel()
        if not (b.shape == i.shape == c.shape) or b.size == 0:
            raise ValueError("border_codes, inner_codes and counts must be non-empty and of one length")
        if (b < 0).any() or (b >= (np.int64(1) << Lb)).any():
            raise ValueError(f"border codes must lie in 0..2^{Lb} - 1 ({Lb} border cells)")
        if (i < 0).any() or (i >= (np.int64(1) << Li)).any():
            raise ValueError(f"inner codes must lie in 0..2^{Li} - 1 ({Li} inner cells)")
        if not np.isfinite(c).all() or (c < 0).any():
            raise ValueError("counts must be finite and non-negative")
        keys, inv = np.unique((b << Li) | i, return_inverse=True)
        cnt = np.bincount(inv, weights=c)
        keep = cnt > 0
        if not keep.any():
            raise ValueError("the table has no mass")
        keys, cnt = keys[keep], cnt[keep]
        borders, binv = np.unique(keys >> Li, return_inverse=True)
        tot = np.bincount(binv, weights=cnt)
        logp = np.log(cnt / tot[binv])
        self.outside, self.unseen, self.pad = int(outside), unseen, pad
        origin = (0, int(origin)) if np.isscalar(origin) else tuple(int(o) for o in origin)  # type: ignore[arg-type]  # numpy's isscalar TypeGuard narrows to generic | complex | bytes
        self.origin = origin
        geo = tiling(self.rows, self.cols, self.inner, pad, origin)
        fill = geo[6] if outside else np.zeros_like(geo[6])
        seg_keys, seg_logp = [keys], [logp]
        fallback = -1
        if unseen == "marginal":
            mi, minv = np.unique(keys & ((np.int64(1) << Li) - 1), return_inverse=True)
            mc = np.bincount(minv, weights=cnt)
            seg_keys.append(mi)
            seg_logp.append(np.log(mc / mc.sum()))
            fallback = 1
        self._compiled = tiles(
            self.rows,
            self.cols,
            geo,
            Li,
            self.inner,
            pad,
            np.zeros(len(fill), np.int64),
            fill,
            seg_keys,
            seg_logp,
            fallback,
        )
        self.keys, self.log_probs = keys, logp
        self.border_codes = borders
        self.row_offsets = np.concatenate([[0], np.cumsum(np.bincount(binv))]).astype(np.int64)
        self.inner_codes = keys & ((np.int64(1) << Li) - 1)
        self.mean_occupancy = table_occupancy(self.inner_codes, cnt, Li)

    def __repr__(self) -> str:
        return f"BorderPatchPrior(inner={self.inner}, borders={self.num_borders}, cells={self.num_cells})"

    @property
    def num_borders(self) -> int:
        return len(self.border_codes)

    @property
    def max_per_border(self) -> int:
        return int(np.diff(self.row_offsets).max())

    def log_prob(self, maps):
        """``sum_t log p(inner_t | border_t)``: ``log p(m)`` up to ``log Z``, ``... x K -> ...``."""
        return tiles_log_prob(self, maps)

    def sample(self, sample_shape=(), generator=None, num_sweeps: int = 100):
        """Maps drawn by ``num_sweeps`` single-cell Gibbs sweeps on the prior alone (from uniform noise;
        with zeros in the table the chain may not reach every map)."""
        return self._gibbs_sample(sample_shape, generator, num_sweeps)
