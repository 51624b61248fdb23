r"""The Python side of priors with a compiled face (Chapter 5): :class:`LocalMapPrior`, the base of the
stencil and table priors, and the geometry of a tiling of the grid (:func:`tiling`).

The compiled conditionals themselves live in :mod:`ogm_ppl.priors.compiled`. A researcher's own prior
reaches the compiled kernels in one of three ways:

* describe it as a stencil of unary + pairwise weights: :class:`~ogm_ppl.priors.StencilPrior`;
* subclass :class:`LocalMapPrior`, set ``rows, cols, ndim, num_cells`` and build ``self._compiled`` with
  one of the bundle builders (:func:`~ogm_ppl.priors.compiled.stencil`,
  :func:`~ogm_ppl.priors.compiled.tiles` over :func:`tiling`), as :class:`~ogm_ppl.priors.PatchTablePrior`
  does; ``log_prob_patch`` and sampling then come for free;
* or any :class:`~ogm_ppl.priors.MapPrior` returning a bundle from ``compiled()`` (a new kind of bundle is
  registered in :mod:`ogm_ppl.priors.compiled`).

A prior with only ``log_prob`` still works, through the generic (slow) path.
"""

from __future__ import annotations

import numpy as np
import torch

from ogm_ppl.priors.base import MapPrior
from ogm_ppl.priors.compiled import CompiledPrior, patch_prior_batch, prior_gibbs_sweeps
from ogm_ppl.priors.compiled.tile_patches import tiles_log_prob_batch

__all__ = ["LocalMapPrior", "grid_shape", "table_occupancy", "tiles_log_prob", "tiling"]


def table_occupancy(codes, weights, L: int) -> float:
    """The cell occupancy of a table of ``L``-cell patches: ``sum_j w_j |c_j| / (L sum_j w_j)`` (``|c|`` the
    set bits of code ``c``), i.e. the mean over the patch's cells of ``P(cell = 1)`` under the table's
    weights (counts or probabilities); 0.5 for an empty table."""
    c = np.asarray(codes, dtype=np.int64).ravel()
    w = np.asarray(weights, dtype=np.float64).ravel()
    if w.sum() <= 0:
        return 0.5
    ones = ((c[:, None] >> np.arange(L, dtype=np.int64)) & 1).sum(1)
    return float((w * ones).sum() / (L * w.sum()))


def grid_shape(shape) -> tuple[int, int, int]:
    """``(rows, cols, ndim)`` of a grid shape ``K``, ``(K,)`` or ``(rows, cols)`` (or a Grid)."""
    if hasattr(shape, "num_cells"):  # a Grid
        shape = shape.shape
    elif isinstance(shape, np.ndarray | torch.Tensor):
        shape = shape.tolist()
    if np.isscalar(shape):
        shape = (int(shape),)  # type: ignore[arg-type]  # numpy's isscalar TypeGuard narrows to generic | complex | bytes
    raw = tuple(shape)
    shape = tuple(int(s) for s in raw)
    if shape != raw or any(s < 1 for s in shape):
        raise ValueError(f"grid shape must hold whole numbers of cells >= 1, got {raw}")
    if len(shape) == 1:
        return 1, shape[0], 1
    if len(shape) == 2:
        return shape[0], shape[1], 2
    raise ValueError(f"grid shape must be (K,) or (rows, cols), got {shape}")


class LocalMapPrior(MapPrior):
    """Base of priors whose compiled face is a bundle they build once (``self._compiled``, returned by
    :meth:`compiled`): the patch conditional :meth:`log_prob_patch` and prior sampling run through the
    same compiled conditionals the Gibbs kernels call. Subclasses set ``rows, cols, ndim, num_cells`` and
    ``self._compiled`` (e.g. :func:`~ogm_ppl.priors.compiled.stencil` or
    :func:`~ogm_ppl.priors.compiled.tiles`)."""

    #: ``log_prob`` is exact (``True``) or known only up to the log partition function (``False``).
    normalised = True
    _compiled: CompiledPrior

    def compiled(self) -> CompiledPrior:
        """The bundle the compiled kernels read (see :mod:`ogm_ppl.priors.compiled`)."""
        return self._compiled

    def cell_log_odds(self):
        return None

    def log_prob_patch(self, maps, cells, configs):
        import torch

        maps = torch.as_tensor(maps)
        squeeze = maps.dim() == 1
        mm = np.ascontiguousarray(maps.reshape(-1, self.num_cells).detach().cpu().numpy() != 0, dtype=np.uint8)
        patch = np.ascontiguousarray(torch.as_tensor(cells).numpy(), dtype=np.int64)
        cf = torch.as_tensor(configs).detach().cpu().numpy().reshape(-1, len(patch)) != 0
        cands = np.ascontiguousarray((cf.astype(np.int64) << np.arange(len(patch))).sum(1), dtype=np.int64)
        out = np.empty((mm.shape[0], len(cands)), np.float64)
        patch_prior_batch(self._compiled, mm, patch, cands, out)
        res = torch.from_numpy(out)
        return res[0] if squeeze else res

    def log_normaliser(self, max_cells: int = 22) -> float:
        """``log Z`` by enumeration of all ``2^K`` maps (small maps only; 0 for normalised priors)."""
        import torch

        if self.normalised:
            return 0.0
        K = self.num_cells
        if K > max_cells:
            raise ValueError(f"log_normaliser enumerates 2^{K} maps; the limit is max_cells = {max_cells}")
        codes = torch.arange(2**K)
        maps = ((codes[:, None] >> torch.arange(K)) & 1).to(torch.float64)
        return float(torch.logsumexp(self.log_prob(maps), 0))

    def _gibbs_sample(self, sample_shape, generator, num_sweeps: int):
        import torch

        shape = torch.Size(sample_shape)
        B = int(np.prod(shape)) if len(shape) else 1
        u = torch.rand((B, self.num_cells), generator=generator, dtype=torch.float64)
        maps = np.ascontiguousarray((u < 0.5).numpy(), dtype=np.uint8)
        seed = int(torch.randint(0, 2**31 - 1, (1,), generator=generator))
        prior_gibbs_sweeps(self._compiled, maps, int(num_sweeps), seed)
        return torch.from_numpy(maps.astype(np.float64)).reshape(*shape, self.num_cells)


def tiling(rows: int, cols: int, tile, pad, origin):
    """Geometry of a tiling of a ``rows x cols`` grid by ``h x w`` tiles, one of which has its top-left
    cell at ``origin``, with windows padded by ``pad = (pr, pc)``. Returns ``(w_dr, w_dc, t_r0, t_c0,
    t_rows, t_cols, off_mask)``: window offsets (tile cells row-major first, then the border ring
    row-major) and, per tile, the key bits of its window cells that lie off the grid."""
    h, w = tile
    pr, pc = pad
    inner = [(r, c) for r in range(h) for c in range(w)]
    ring = [(r, c) for r in range(-pr, h + pr) for c in range(-pc, w + pc) if not (0 <= r < h and 0 <= c < w)]
    off = np.array(inner + ring, dtype=np.int64).reshape(-1, 2)
    r0 = int(origin[0]) % h
    c0 = int(origin[1]) % w
    r0 = r0 - h if r0 else 0
    c0 = c0 - w if c0 else 0
    t_rows = -(-(rows - r0) // h)
    t_cols = -(-(cols - c0) // w)
    ti, tj = np.meshgrid(np.arange(t_rows), np.arange(t_cols), indexing="ij")
    ar = (r0 + ti.ravel() * h)[:, None] + off[None, :, 0]
    ac = (c0 + tj.ravel() * w)[:, None] + off[None, :, 1]
    outside = ~((ar >= 0) & (ar < rows) & (ac >= 0) & (ac < cols))
    off_mask = (outside.astype(np.int64) << np.arange(len(off), dtype=np.int64)).sum(1)
    return (
        np.ascontiguousarray(off[:, 0]),
        np.ascontiguousarray(off[:, 1]),
        r0,
        c0,
        int(t_rows),
        int(t_cols),
        np.ascontiguousarray(off_mask, dtype=np.int64),
    )


def tiles_log_prob(prior, maps):
    """``sum_t log phi_t(m)`` for ``... x K`` maps, through the compiled tile lookups."""
    import torch

    maps = torch.as_tensor(maps)
    batch = maps.shape[:-1]
    mm = np.ascontiguousarray(maps.reshape(-1, prior.num_cells).detach().cpu().numpy() != 0, dtype=np.uint8)
    out = np.empty(mm.shape[0], np.float64)
    tiles_log_prob_batch(prior._compiled, mm, out)
    return torch.from_numpy(out).reshape(batch)
