"""Sufficient statistics of maps for fitting a pattern field: per cell the key of its pseudo-likelihood
conditional (its ``(2w - 1)^2`` neighbourhood, at two scales also its pooled parent's), the distinct keys and
their counts (:class:`FieldStats`), the counts of the window codes wholly in known cells, and the per-window
orbit frequencies of sampled chains; and crops of the training maps to start chains from (:func:`data_crops`).
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

import numba as nb
import numpy as np

from ogm_ppl.priors.compiled.field import field_window_codes
from ogm_ppl.priors.learn import _as_pair as _as_pair_checked
from ogm_ppl.priors.pattern_field import symmetry_orbits


@nb.njit(cache=True)
def _nbhd_keys(g, bad, w, two):
    """Per eligible cell of a 2D grid the key of its conditional: bits ``0..S^2-1`` its ``S x S``
    neighbourhood (``S = 2w - 1``, centre included); a cell is eligible when that neighbourhood lies in
    the grid and in known cells (``bad``: 1 for unknown cells). With ``two`` also the two-scale keys of
    the cells whose parent's pooled ``S x S`` neighbourhood lies in the pooled grid and in known pooled
    cells: bit ``S^2`` = the rest of the cell's ``2 x 2`` block is free, bits ``S^2 + 1 ..`` the pooled
    neighbourhood (parent cleared). Returns ``(keys1, keys2)``."""
    R, C = g.shape
    S = 2 * w - 1
    h = w - 1
    P = (R + 1) // 2
    Q = (C + 1) // 2
    pg = np.zeros((P, Q), np.uint8)
    pbad = np.zeros((P, Q), np.uint8)
    for r in range(R):
        for c in range(C):
            pg[r >> 1, c >> 1] |= g[r, c]
            pbad[r >> 1, c >> 1] |= bad[r, c]
    # prefix sums of unknown cells, to test a neighbourhood in O(1)
    cb = np.zeros((R + 1, C + 1), np.int64)
    for r in range(R):
        for c in range(C):
            cb[r + 1, c + 1] = cb[r, c + 1] + cb[r + 1, c] - cb[r, c] + bad[r, c]
    pb = np.zeros((P + 1, Q + 1), np.int64)
    for r in range(P):
        for c in range(Q):
            pb[r + 1, c + 1] = pb[r, c + 1] + pb[r + 1, c] - pb[r, c] + pbad[r, c]
    out1 = np.empty(R * C, np.int64)
    out2 = np.empty(R * C if two else 0, np.int64)
    n1 = 0
    n2 = 0
    for r in range(h, R - h):
        for c in range(h, C - h):
            if cb[r + h + 1, c + h + 1] - cb[r - h, c + h + 1] - cb[r + h + 1, c - h] + cb[r - h, c - h] > 0:
                continue
            key = np.int64(0)
            for a in range(S):
                for b in range(S):
                    if g[r - h + a, c - h + b]:
                        key |= np.int64(1) << (a * S + b)
            out1[n1] = key
            n1 += 1
            if two:
                pr = r >> 1
                pc = c >> 1
                if pr < h or pc < h or pr + h >= P or pc + h >= Q:
                    continue
                if (
                    pb[pr + h + 1, pc + h + 1] - pb[pr - h, pc + h + 1] - pb[pr + h + 1, pc - h] + pb[pr - h, pc - h]
                    > 0
                ):
                    continue
                free = 1
                for i in range(2 * pr, min(2 * pr + 2, R)):
                    for j in range(2 * pc, min(2 * pc + 2, C)):
                        if (i != r or j != c) and g[i, j]:
                            free = 0
                key |= np.int64(free) << (S * S)
                for a in range(S):
                    for b in range(S):
                        if (a != h or b != h) and pg[pr - h + a, pc - h + b]:
                            key |= np.int64(1) << (S * S + 1 + a * S + b)
                out2[n2] = key
                n2 += 1
    return out1[:n1], out2[:n2]


def _pooled_np(g: np.ndarray) -> np.ndarray:
    R, C = g.shape
    x = np.zeros((R + R % 2, C + C % 2), np.uint8)
    x[:R, :C] = g
    return x.reshape(x.shape[0] // 2, 2, x.shape[1] // 2, 2).max((1, 3))


@dataclass
class FieldStats:
    """Sufficient statistics of a set of maps for fitting a ``w x w`` field at one or two scales:
    ``keys1``/``counts1`` the distinct one-scale conditional keys (:func:`_nbhd_keys`) and their counts,
    ``keys2``/``counts2`` the two-scale ones (empty when ``scales == 1``), ``win1`` (``2^(w w)``) the counts
    of the window codes wholly in known cells, ``win2`` those of the pooled grid."""

    w: int
    scales: int
    keys1: np.ndarray
    counts1: np.ndarray
    keys2: np.ndarray
    counts2: np.ndarray
    win1: np.ndarray
    win2: np.ndarray
    n_maps: int = 0
    n_cells: int = 0

    def orbit_freq(self, scale: int = 1) -> np.ndarray:
        """Per-window frequency of each orbit (``n_orbits``)."""
        orbit, n = symmetry_orbits(self.w)
        c = self.win1 if scale == 1 else self.win2
        return np.bincount(orbit, c.astype(np.float64), n) / max(c.sum(), 1)


def _as_pair(item, index: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """``(occupancy, known)`` bool arrays of a map as :func:`~ogm_ppl.priors.learn.count_tables` takes it (checked
    the same way), every cell known where it says nothing of them."""
    occ, known = _as_pair_checked(item, index)
    return occ, np.ones_like(occ) if known is None else known


def field_stats(maps: Iterable, w: int = 3, scales: int = 1) -> FieldStats:
    """:class:`FieldStats` of a stream of maps (``H x W`` bool arrays, ``(occupancy, known)`` pairs, or
    :class:`~ogm_ppl.datasets.floorplans.FloorPlan`\\ s)."""
    if scales not in (1, 2):
        raise ValueError(f"scales must be 1 or 2, got {scales}")
    if scales == 2 and 2 * (2 * w - 1) ** 2 + 1 > 63:
        raise ValueError(f"a two-scale key of w = {w} does not fit 63 bits")
    n_codes = 1 << (w * w)
    win1 = np.zeros(n_codes, np.int64)
    win2 = np.zeros(n_codes, np.int64)
    acc: list[list[np.ndarray]] = [[], [], [], []]
    n_maps = n_cells = 0
    for index, item in enumerate(maps):
        occ, known = _as_pair(item, index)
        g = np.ascontiguousarray(occ & known, np.uint8)
        bad = np.ascontiguousarray(~known, np.uint8)
        for i, k in enumerate(_nbhd_keys(g, bad, w, scales == 2)):
            u, c = np.unique(k, return_counts=True)
            acc[2 * i].append(u)
            acc[2 * i + 1].append(c)
        c1 = field_window_codes(g, w)
        b1 = field_window_codes(bad, w)
        win1 += np.bincount(c1[b1 == 0], minlength=n_codes)
        pg, pbad = _pooled_np(g), _pooled_np(bad)
        c2 = field_window_codes(pg, w)
        b2 = field_window_codes(pbad, w)
        win2 += np.bincount(c2[b2 == 0], minlength=n_codes)
        n_maps += 1
        n_cells += occ.size
    return FieldStats(w, scales, *_merge(acc[0], acc[1]), *_merge(acc[2], acc[3]), win1, win2, n_maps, n_cells)


def _merge(keys: list[np.ndarray], counts: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    if not keys:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    u, inv = np.unique(np.concatenate(keys), return_inverse=True)
    return u.astype(np.int64), np.bincount(inv, np.concatenate(counts)).astype(np.int64)


def _chain_freq(maps: np.ndarray, size: int, w: int, orbit: np.ndarray, n: int, two: bool):
    n_codes = 1 << (w * w)
    c1 = np.zeros(n_codes, np.float64)
    c2 = np.zeros(n_codes, np.float64)
    for m in maps:
        g = m.reshape(size, size)
        c1 += np.bincount(field_window_codes(g, w).ravel(), minlength=n_codes)
        if two:
            c2 += np.bincount(field_window_codes(_pooled_np(g), w).ravel(), minlength=n_codes)
    f1 = np.bincount(orbit, c1, n) / c1.sum()
    f2 = np.bincount(orbit, c2, n) / max(c2.sum(), 1.0)
    return f1, f2


def data_crops(maps: Iterable, chains: int, size: int, seed: int = 0, tries: int = 200) -> np.ndarray:
    """``chains x size^2`` uint8 crops of the maps (``(occupancy, known)`` pairs or bool arrays), each at a
    seeded random map and offset, preferring crops wholly in known cells (unknown cells read as occupied)."""
    pairs = [_as_pair(m, i) for i, m in enumerate(maps)]
    pairs = [(o, k) for o, k in pairs if o.shape[0] >= size and o.shape[1] >= size]
    if not pairs:
        raise ValueError(f"no map is at least {size} x {size} cells")
    rng = np.random.default_rng(seed)
    out = np.empty((chains, size * size), np.uint8)
    for b in range(chains):
        for _ in range(tries):
            o, k = pairs[int(rng.integers(len(pairs)))]
            r = int(rng.integers(o.shape[0] - size + 1))
            c = int(rng.integers(o.shape[1] - size + 1))
            if k[r : r + size, c : c + size].all():
                break
        out[b] = (o | ~k)[r : r + size, c : c + size].ravel()
    return out
