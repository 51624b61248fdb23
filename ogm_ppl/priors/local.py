r"""Local conditionals of correlated priors, in a form compiled kernels read (Chapter 5, Eq. 5.1).

A Gibbs sweep must never evaluate a prior's whole-map ``log_prob`` per update. Priors that want the
compiled path describe themselves by one :class:`LocalPrior` bundle of arrays (a ``typing.NamedTuple``,
which numba takes as one argument). Two families cover Chapter 5:

* **stencil** (``kind = STENCIL``): a pairwise binary field on a neighbourhood stencil,

  .. math:: \log \tilde p(m) = \sum_k m_k \Big(h_k + \sum_{d:\,k+d \in G} a_d\Big)
            + \tfrac12 \sum_k \sum_{d:\,k+d \in G} J_d\, m_k m_{k+d},

  so that the conditional log-odds of a cell is affine in its neighbours,
  ``l(m_k | m_-k) = h_k + sum_{d: k+d in G} (a_d + J_d m_{k+d})`` (``J_d = J_{-d}``). The MRF of
  Section 5.2.1 is ``a_d = log psi``, ``J_d = -2 log psi``: ``l = l(lambda) + (n0 - n1) log psi``.
* **tiles** (``kind = TILES``): ``log p~(m) = sum_t log phi(key_t(m))`` over the tiles ``t`` of a fixed
  tiling of the plane by ``h x w`` rectangles; ``key_t`` packs the tile's *window* (the tile and a ring
  of ``pad`` border cells) into an integer: bit ``i`` = window cell ``i``, the tile's own cells first
  (row-major), then the border ring (row-major in the window). Window cells off the grid read as the
  tile's ``fill`` bits. ``phi`` is a sparse table (sorted keys and their log values) per *segment*; a
  tile names its segment (e.g. the marginal table of tiles cut by the grid edge). Keys missing from a
  segment fall back to segment ``fallback`` (keyed by the tile's own bits only) when its border is
  unseen, else have ``phi = 0``. The patch tables of Section 5.2.2 (``pad = 0``) and the
  border-conditioned tables of Section 5.2.3 (``pad = 1``) are both of this kind.

The numba functions below are the only place the kernels look at a prior: :func:`cell_log_odds`
(single-cell Gibbs, ICM) and :func:`patch_prior_weights` / :func:`tile_candidates` (patch Gibbs, with
sparse enumeration of the configurations a table allows given the border).

A researcher's own prior reaches the compiled path by describing itself as a stencil
(:class:`~ogm_ppl.priors.StencilPrior`: unary weights + pairwise weights per offset) or as tiles
(subclass :class:`TiledPrior` with arrays); a prior with only ``log_prob`` still works through the
generic (slow) path.
"""

from __future__ import annotations

from typing import NamedTuple

import numba as nb
import numpy as np

from .base import MapPrior

__all__ = ["LocalPrior", "LocalMapPrior", "STENCIL", "TILES", "cell_log_odds", "patch_prior_weights",
           "tile_candidates", "local_of"]  # fmt: skip

STENCIL, TILES = 0, 1
_I = np.zeros(0, np.int64)
_F = np.zeros(0, np.float64)


class LocalPrior(NamedTuple):
    """The arrays a compiled kernel reads (see the module docstring). Unused fields are empty."""

    kind: int
    rows: int
    cols: int
    # stencil
    unary: np.ndarray  # K float64, h_k
    s_dr: np.ndarray  # D int64
    s_dc: np.ndarray  # D int64
    s_bias: np.ndarray  # D float64, a_d
    s_coup: np.ndarray  # D float64, J_d
    # tiles
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


def stencil_local(rows, cols, unary, dr, dc, bias, coup) -> LocalPrior:
    """A :class:`LocalPrior` of the stencil kind."""
    return LocalPrior(STENCIL, int(rows), int(cols), np.ascontiguousarray(unary, np.float64),
                      np.ascontiguousarray(dr, np.int64), np.ascontiguousarray(dc, np.int64),
                      np.ascontiguousarray(bias, np.float64), np.ascontiguousarray(coup, np.float64),
                      _I, _I, 0, 1, 1, 0, 0, 0, 0, 0, 0, _I, _I, np.zeros(1, np.int64), _I, _F, -1)  # fmt: skip


def local_of(prior) -> LocalPrior | None:
    """The prior's :class:`LocalPrior` (``prior.local()``), or ``None`` for priors without one."""
    fn = getattr(prior, "local", None)
    return fn() if callable(fn) else None


# ------------------------------------------------------------------ stencil
@nb.njit(cache=True)
def stencil_cell_log_odds(lp, k, m):
    """``l(m_k | m_-k) = h_k + sum_{d in grid} (a_d + J_d m_{k+d})``."""
    cols = lp.cols
    r = k // cols
    c = k - r * cols
    lo = lp.unary[k]
    for d in range(lp.s_dr.shape[0]):
        rr = r + lp.s_dr[d]
        cc = c + lp.s_dc[d]
        if 0 <= rr < lp.rows and 0 <= cc < cols:
            lo += lp.s_bias[d]
            if m[rr * cols + cc]:
                lo += lp.s_coup[d]
    return lo


# ------------------------------------------------------------------ tiles
@nb.njit(cache=True, inline="always")
def tile_key(lp, t, m):
    """The window key of tile ``t`` in map ``m``."""
    ti = t // lp.t_cols
    tj = t - ti * lp.t_cols
    ar = lp.t_r0 + ti * lp.t_h
    ac = lp.t_c0 + tj * lp.t_w
    key = lp.t_fill[t]
    for i in range(lp.w_dr.shape[0]):
        r = ar + lp.w_dr[i]
        c = ac + lp.w_dc[i]
        if 0 <= r < lp.rows and 0 <= c < lp.cols and m[r * lp.cols + c]:
            key |= np.int64(1) << i
    return key


@nb.njit(cache=True)
def _lower(keys, lo, hi, key):
    while lo < hi:
        mid = (lo + hi) >> 1
        if keys[mid] < key:
            lo = mid + 1
        else:
            hi = mid
    return lo


@nb.njit(cache=True, inline="always")
def key_log_factor(lp, s, key):
    """``log phi(key)`` in segment ``s`` (fallback for an unseen border; ``-inf`` if absent)."""
    a, b = lp.seg_off[s], lp.seg_off[s + 1]
    i = _lower(lp.keys, a, b, key)
    if i < b and lp.keys[i] == key:
        return lp.logp[i]
    if lp.fallback >= 0 and lp.w_dr.shape[0] > lp.n_inner:
        border = key >> lp.n_inner
        j = _lower(lp.keys, a, b, border << lp.n_inner)
        if j == b or (lp.keys[j] >> lp.n_inner) != border:  # border never seen: back off
            fa, fb = lp.seg_off[lp.fallback], lp.seg_off[lp.fallback + 1]
            inner = key & ((np.int64(1) << lp.n_inner) - 1)
            q = _lower(lp.keys, fa, fb, inner)
            if q < fb and lp.keys[q] == inner:
                return lp.logp[q]
    return -np.inf


@nb.njit(cache=True, inline="always")
def tile_log_factor(lp, t, m):
    return key_log_factor(lp, lp.t_seg[t], tile_key(lp, t, m))


@nb.njit(cache=True)
def tiles_touching(lp, r, c, out, n):
    """Append to ``out[:n]`` the tiles whose window holds cell ``(r, c)`` (no duplicates); new ``n``."""
    # tile i's window rows are [t_r0 + i h - pad_r, t_r0 + i h + h - 1 + pad_r]
    i0 = max((r - lp.pad_r - lp.t_r0) // lp.t_h - 1, 0)
    i1 = min((r + lp.pad_r - lp.t_r0) // lp.t_h, lp.t_rows - 1)
    j0 = max((c - lp.pad_c - lp.t_c0) // lp.t_w - 1, 0)
    j1 = min((c + lp.pad_c - lp.t_c0) // lp.t_w, lp.t_cols - 1)
    for i in range(i0, i1 + 1):
        ar = lp.t_r0 + i * lp.t_h
        if r < ar - lp.pad_r or r > ar + lp.t_h - 1 + lp.pad_r:
            continue
        for j in range(j0, j1 + 1):
            ac = lp.t_c0 + j * lp.t_w
            if c < ac - lp.pad_c or c > ac + lp.t_w - 1 + lp.pad_c:
                continue
            t = i * lp.t_cols + j
            dup = False
            for q in range(n):
                if out[q] == t:
                    dup = True
                    break
            if not dup:
                out[n] = t
                n += 1
    return n


@nb.njit(cache=True)
def _tiles_of_patch(lp, patch, out):
    n = 0
    for i in range(patch.shape[0]):
        k = patch[i]
        if k >= 0:
            r = k // lp.cols
            n = tiles_touching(lp, r, k - r * lp.cols, out, n)
    return n


@nb.njit(cache=True)
def _touch_capacity(lp, L):
    per = ((lp.t_h + 2 * lp.pad_r) // lp.t_h + 2) * ((lp.t_w + 2 * lp.pad_c) // lp.t_w + 2)
    return max(L, 1) * per


# ------------------------------------------------------------------ shared entry points
@nb.njit(cache=True)
def tile_cell_log_odds(lp, k, m):
    """:func:`cell_log_odds` of a tiles prior: the factors of the tiles whose window holds ``k``."""
    r = k // lp.cols
    c = k - r * lp.cols
    i0 = max((r - lp.pad_r - lp.t_r0) // lp.t_h - 1, 0)
    i1 = min((r + lp.pad_r - lp.t_r0) // lp.t_h, lp.t_rows - 1)
    j0 = max((c - lp.pad_c - lp.t_c0) // lp.t_w - 1, 0)
    j1 = min((c + lp.pad_c - lp.t_c0) // lp.t_w, lp.t_cols - 1)
    old = m[k]
    s1 = 0.0
    s0 = 0.0
    for i in range(i0, i1 + 1):
        ar = lp.t_r0 + i * lp.t_h
        if r < ar - lp.pad_r or r > ar + lp.t_h - 1 + lp.pad_r:
            continue
        for j in range(j0, j1 + 1):
            ac = lp.t_c0 + j * lp.t_w
            if c < ac - lp.pad_c or c > ac + lp.t_w - 1 + lp.pad_c:
                continue
            t = i * lp.t_cols + j
            m[k] = 1
            s1 += tile_log_factor(lp, t, m)
            m[k] = 0
            s0 += tile_log_factor(lp, t, m)
    m[k] = old
    return s1 - s0


@nb.njit(cache=True)
def cell_log_odds(lp, k, m):
    """``log p(m_k = 1, m_-k) - log p(m_k = 0, m_-k)`` under the prior (``nan`` if both are impossible)."""
    if lp.kind == STENCIL:
        return stencil_cell_log_odds(lp, k, m)
    return tile_cell_log_odds(lp, k, m)


@nb.njit(cache=True)
def _set_bits(patch, m, w):
    bit = 0
    for i in range(patch.shape[0]):
        c = patch[i]
        if c >= 0:
            m[c] = (w >> bit) & 1
            bit += 1


@nb.njit(cache=True)
def patch_prior_weights(lp, patch, m, cands, n, out):
    """``out[j] = log p(patch = cands[j], rest)`` up to a constant in ``j`` (bit ``b`` of a candidate =
    the ``b``-th live cell of ``patch``; ``-1`` entries are not part of the patch). ``m`` is restored."""
    L = patch.shape[0]
    saved = np.empty(L, np.uint8)
    for i in range(L):
        if patch[i] >= 0:
            saved[i] = m[patch[i]]
    if lp.kind == STENCIL:
        # fields with the patch cleared, plus couplings inside the patch
        _set_bits(patch, m, 0)
        nl = 0
        for i in range(L):
            if patch[i] >= 0:
                nl += 1
        field = np.empty(max(nl, 1), np.float64)
        live = np.empty(max(nl, 1), np.int64)
        b = 0
        for i in range(L):
            if patch[i] >= 0:
                field[b] = stencil_cell_log_odds(lp, patch[i], m)
                live[b] = patch[i]
                b += 1
        pi = np.empty(nl * nl, np.int64)
        pj = np.empty(nl * nl, np.int64)
        pw = np.empty(nl * nl, np.float64)
        npair = 0
        for x in range(nl):
            rx = live[x] // lp.cols
            cx = live[x] - rx * lp.cols
            for y in range(x + 1, nl):
                ry = live[y] // lp.cols
                cy = live[y] - ry * lp.cols
                for d in range(lp.s_dr.shape[0]):
                    if ry - rx == lp.s_dr[d] and cy - cx == lp.s_dc[d]:
                        pi[npair] = x
                        pj[npair] = y
                        pw[npair] = lp.s_coup[d]
                        npair += 1
        for j in range(n):
            w = cands[j]
            s = 0.0
            for x in range(nl):
                if (w >> x) & 1:
                    s += field[x]
            for q in range(npair):
                if (w >> pi[q]) & 1 and (w >> pj[q]) & 1:
                    s += pw[q]
            out[j] = s
    else:
        touch = np.empty(_touch_capacity(lp, L), np.int64)
        nt = _tiles_of_patch(lp, patch, touch)
        for j in range(n):
            _set_bits(patch, m, cands[j])
            s = 0.0
            for q in range(nt):
                s += tile_log_factor(lp, touch[q], m)
                if s == -np.inf:
                    break
            out[j] = s
    for i in range(L):
        if patch[i] >= 0:
            m[patch[i]] = saved[i]


@nb.njit(cache=True)
def tile_of_anchor(lp, r0, c0, h, w):
    """The tile whose cells are exactly the ``h x w`` rectangle at ``(r0, c0)``, or ``-1``."""
    if lp.kind != TILES or h != lp.t_h or w != lp.t_w:
        return -1
    dr = r0 - lp.t_r0
    dc = c0 - lp.t_c0
    if dr % lp.t_h != 0 or dc % lp.t_w != 0:
        return -1
    i = dr // lp.t_h
    j = dc // lp.t_w
    if i < 0 or j < 0 or i >= lp.t_rows or j >= lp.t_cols:
        return -1
    return i * lp.t_cols + j


@nb.njit(cache=True)
def tile_candidates(lp, t, patch, pinned, m, cands):
    """Configurations of tile ``t`` (whose cells, row-major, are ``patch``; ``-1`` off the grid or
    pinned) that its own factor allows given the current border: the sparse support of Section 5.2.2 /
    5.2.3. Written to ``cands`` as live-bit codes; returns how many (``-1`` if ``cands`` is too small)."""
    key = tile_key(lp, t, m)
    Li = lp.n_inner
    border = key >> Li
    s = lp.t_seg[t]
    a, b = lp.seg_off[s], lp.seg_off[s + 1]
    lo = _lower(lp.keys, a, b, border << Li)
    hi = _lower(lp.keys, a, b, (border + 1) << Li)
    if lo == hi and lp.fallback >= 0 and lp.w_dr.shape[0] > Li:
        lo, hi = lp.seg_off[lp.fallback], lp.seg_off[lp.fallback + 1]
    fill = lp.t_fill[t]
    ti = t // lp.t_cols
    ar = lp.t_r0 + ti * lp.t_h
    ac = lp.t_c0 + (t - ti * lp.t_cols) * lp.t_w
    n = 0
    for q in range(lo, hi):
        inner = lp.keys[q] & ((np.int64(1) << Li) - 1)
        ok = True
        code = 0
        bit = 0
        for i in range(Li):
            v = (inner >> i) & 1
            if patch[i] >= 0:
                if v:
                    code |= np.int64(1) << bit
                bit += 1
            else:
                r = ar + lp.w_dr[i]
                c = ac + lp.w_dc[i]
                if 0 <= r < lp.rows and 0 <= c < lp.cols:
                    if v:  # a pinned cell is free
                        ok = False
                        break
                elif v != ((fill >> i) & 1):
                    ok = False
                    break
        if ok:
            if n >= cands.shape[0]:
                return -1
            cands[n] = code
            n += 1
    return n


@nb.njit(cache=True)
def prior_gibbs_sweeps(lp, maps, num_sweeps, seed):
    """Single-cell Gibbs sweeps on the prior alone, for each row of ``maps`` (``B x K`` uint8), in place."""
    np.random.seed(seed)
    for b in range(maps.shape[0]):
        m = maps[b]
        for _ in range(num_sweeps):
            for k in range(m.shape[0]):
                lo = stencil_cell_log_odds(lp, k, m) if lp.kind == STENCIL else tile_cell_log_odds(lp, k, m)
                if lo != lo:
                    continue
                u = np.random.random()
                if lo >= 0:
                    m[k] = 1 if u * (1.0 + np.exp(-lo)) < 1.0 else 0
                else:
                    e = np.exp(lo)
                    m[k] = 1 if u * (1.0 + e) < e else 0


@nb.njit(cache=True)
def patch_prior_batch(lp, maps, patch, cands, out):
    """:func:`patch_prior_weights` for every row of ``maps`` (``B x K`` uint8) -> ``out`` (``B x W``)."""
    for b in range(maps.shape[0]):
        patch_prior_weights(lp, patch, maps[b], cands, cands.shape[0], out[b])


@nb.njit(cache=True)
def tiles_log_prob_batch(lp, maps, out):
    """``sum_t log phi_t(m)`` for every row of ``maps`` (``B x K`` uint8)."""
    T = lp.t_rows * lp.t_cols
    for b in range(maps.shape[0]):
        s = 0.0
        for t in range(T):
            s += tile_log_factor(lp, t, maps[b])
        out[b] = s


# ------------------------------------------------------------------ Python side
def grid_shape(shape) -> tuple[int, int, int]:
    """``(rows, cols, ndim)`` of a grid shape ``K``, ``(K,)`` or ``(rows, cols)`` (or a Grid)."""
    shape = getattr(shape, "shape", shape)
    if np.isscalar(shape):
        shape = (int(shape),)
    shape = tuple(int(s) for s in shape)
    if len(shape) == 1:
        return 1, shape[0], 1
    if len(shape) == 2:
        return shape[0], shape[1], 2
    raise ValueError(f"grid shape must be (K,) or (rows, cols), got {shape}")


class LocalMapPrior(MapPrior):
    """Mixin of priors with a compiled local conditional (:meth:`local`): the patch conditional
    :meth:`log_prob_patch` and prior sampling both run through the same compiled functions the Gibbs
    kernels call. Subclasses set ``rows, cols, ndim, num_cells`` and build ``self._local``."""

    #: ``log_prob`` is exact (``True``) or known only up to the log partition function (``False``).
    normalised = True
    _local: LocalPrior

    def local(self) -> LocalPrior:
        """The :class:`LocalPrior` bundle the compiled kernels read."""
        return self._local

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
        patch_prior_batch(self._local, mm, patch, cands, out)
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
        prior_gibbs_sweeps(self._local, maps, int(num_sweeps), seed)
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
    return (np.ascontiguousarray(off[:, 0]), np.ascontiguousarray(off[:, 1]), r0, c0, int(t_rows), int(t_cols),
            np.ascontiguousarray(off_mask, dtype=np.int64))  # fmt: skip


def tiles_local(rows, cols, geometry, n_inner, tile, pad, t_seg, t_fill, seg_keys, seg_logp, fallback=-1):
    """A :class:`LocalPrior` of the tiles kind from per-segment (keys, log-values) lists."""
    w_dr, w_dc, r0, c0, t_rows, t_cols, _ = geometry
    seg_off = np.zeros(len(seg_keys) + 1, np.int64)
    keys, logp = [], []
    for s, (k, lp) in enumerate(zip(seg_keys, seg_logp)):
        order = np.argsort(k, kind="stable")
        keys.append(np.asarray(k, np.int64)[order])
        logp.append(np.asarray(lp, np.float64)[order])
        seg_off[s + 1] = seg_off[s] + len(k)
    keys = np.ascontiguousarray(np.concatenate(keys) if keys else _I, np.int64)
    logp = np.ascontiguousarray(np.concatenate(logp) if logp else _F, np.float64)
    return LocalPrior(TILES, int(rows), int(cols), _F, _I, _I, _F, _F, w_dr, w_dc, int(n_inner), int(tile[0]),
                      int(tile[1]), int(r0), int(c0), int(t_rows), int(t_cols), int(pad[0]), int(pad[1]),
                      np.ascontiguousarray(t_seg, np.int64), np.ascontiguousarray(t_fill, np.int64), seg_off,
                      keys, logp, int(fallback))  # fmt: skip


def tiles_log_prob(prior, maps):
    """``sum_t log phi_t(m)`` for ``... x K`` maps, through the compiled tile lookups."""
    import torch

    maps = torch.as_tensor(maps)
    batch = maps.shape[:-1]
    mm = np.ascontiguousarray(maps.reshape(-1, prior.num_cells).detach().cpu().numpy() != 0, dtype=np.uint8)
    out = np.empty(mm.shape[0], np.float64)
    tiles_log_prob_batch(prior._local, mm, out)
    return torch.from_numpy(out).reshape(batch)
