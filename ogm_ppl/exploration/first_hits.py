r"""Posterior samples of the map as bit sets, and the compiled kernels that walk candidate rays through them.

``S`` maps of ``K`` cells are packed per cell into ``W = ceil(S / 64)`` words (:func:`pack_samples`: bit
``s % 64`` of word ``s // 64`` is sample ``s``), so one ray walk serves every sample at once: a word ``alive``
holds the samples in which the beam has met no occupied cell yet, and the samples whose first hit is a cell are
``alive & occupied``. Each candidate's samples are conditioned on its own cell being free.

* :func:`first_hits_kernel` — ``p(f_r = kappa)``, the weight of the samples whose first occupied cell on ray
  ``r`` is ``kappa`` (column ``len_r``: none), over the weight of the samples with the candidate's cell free;
* :func:`new_cells_kernel` — ``sum_s w_s |union_b V_b(m_s) \ O|`` per candidate, ``V_b`` the cells beam ``b``
  crosses before (or up to) its first hit and ``O`` the observed cells.
"""

from __future__ import annotations

from typing import NamedTuple

import numba as nb
import numpy as np
import torch

from ogm_ppl.exploration.rays import RayTable

__all__ = [
    "PackedSamples",
    "ctz",
    "first_hits_kernel",
    "new_cells_kernel",
    "pack_samples",
    "packed_samples",
    "sample_weights",
    "valid_mask",
    "weight_of",
]


class PackedSamples(NamedTuple):
    """The samples as the kernels read them (one numba argument): ``packed`` ``K x W`` uint64 bit sets
    (:func:`pack_samples`), ``w`` ``S`` float64 weights summing to one, ``valid_mask`` ``W`` uint64 (the bits
    of real samples in each word)."""

    packed: np.ndarray
    w: np.ndarray
    valid_mask: np.ndarray


def packed_samples(samples, K: int, weights=None) -> PackedSamples:
    """:class:`PackedSamples` of ``S x K`` 0/1 maps and their optional weights (default: equal)."""
    packed, S = pack_samples(samples, K)
    w = sample_weights(weights, S)
    return PackedSamples(packed, w, valid_mask(S))


def pack_samples(samples, K: int) -> tuple[np.ndarray, int]:
    """``S x K`` 0/1 maps (or grid-shaped, ``S x rows x cols``, as marginals may be) -> ``K x W`` uint64 bit sets
    (bit ``s % 64`` of word ``s // 64``: sample ``s``)."""
    if isinstance(samples, torch.Tensor):
        samples = samples.detach().cpu().numpy()
    a = np.asarray(samples)
    if a.dtype.kind not in "biuf":
        raise TypeError(f"samples must be a 0/1 array of maps, got dtype {a.dtype}")
    if a.ndim > 2 and int(np.prod(a.shape[1:])) == K:
        a = a.reshape(a.shape[0], K)
    if a.ndim != 2 or a.shape[1] != K:
        raise ValueError(f"samples must have shape S x {K} (S maps of the grid's cells, or grid-shaped), got {a.shape}")
    S = a.shape[0]
    if S == 0:
        raise ValueError("samples is empty: the information gain needs at least one posterior sample")
    if a.dtype != np.bool_:
        if a.dtype.kind == "f" and not np.isfinite(a).all():
            raise ValueError("samples holds NaN or infinite values")
        if ((a != 0) & (a != 1)).any():
            raise ValueError("samples must hold only 0 and 1")
    bits = np.packbits(np.ascontiguousarray((a != 0).T), axis=1, bitorder="little")  # K x ceil(S/8)
    W = (S + 63) // 64
    out = np.zeros((K, W * 8), dtype=np.uint8)
    out[:, : bits.shape[1]] = bits
    return out.view("<u8").astype(np.uint64, copy=False).reshape(K, W), S


def sample_weights(weights, S: int) -> np.ndarray:
    """``S`` weights normalised to sum to one (``None``: ``1/S`` each); ``ValueError`` if not ``S`` finite
    non-negative numbers, not all zero."""
    if weights is None:
        return np.full(S, 1.0 / S)
    w = torch.as_tensor(weights, dtype=torch.float64).detach().cpu().numpy().reshape(-1)
    if w.shape != (S,):
        raise ValueError(f"weights must hold one number per sample ({S}), got shape {w.shape}")
    if not np.isfinite(w).all() or (w < 0).any() or w.sum() <= 0:
        raise ValueError("weights must be finite, non-negative and not all zero")
    return w / w.sum()


def valid_mask(S: int) -> np.ndarray:
    """``W`` uint64 words with the bits of samples ``0..S-1`` set."""
    W = (S + 63) // 64
    mask = np.full(W, np.uint64(0xFFFFFFFFFFFFFFFF), dtype=np.uint64)
    if S % 64:
        mask[-1] = np.uint64((1 << (S % 64)) - 1)
    return mask


@nb.njit(cache=True, inline="always")
def ctz(x):
    """Index of the lowest set bit of a non-zero uint64."""
    n = 0
    if (x & np.uint64(0xFFFFFFFF)) == 0:
        n += 32
        x >>= np.uint64(32)
    if (x & np.uint64(0xFFFF)) == 0:
        n += 16
        x >>= np.uint64(16)
    if (x & np.uint64(0xFF)) == 0:
        n += 8
        x >>= np.uint64(8)
    if (x & np.uint64(0xF)) == 0:
        n += 4
        x >>= np.uint64(4)
    if (x & np.uint64(0x3)) == 0:
        n += 2
        x >>= np.uint64(2)
    if (x & np.uint64(0x1)) == 0:
        n += 1
    return n


@nb.njit(cache=True, inline="always")
def weight_of(x, word, w):
    """Sum of ``w[s]`` over the samples ``s`` whose bits are set in word ``word`` value ``x``."""
    acc = 0.0
    one = np.uint64(1)
    while x != 0:
        acc += w[word * 64 + ctz(x)]
        x &= x - one
    return acc


@nb.njit(cache=True)
def first_hits_kernel(samples: PackedSamples, rays: RayTable, Wmax):
    """Per ray, the weight of the samples with first hit at each kappa (last column: none), conditioned
    on the pose cell free: ``pf`` ``C*B x (Wmax + 1)`` float64 (``Wmax``: the longest ray); ``totals[c]`` the
    weight of the samples with candidate ``c``'s cell free."""
    packed, w, valid_mask = samples.packed, samples.w, samples.valid_mask
    offsets, cells, pose_cells, B = rays.offsets, rays.cells, rays.pose_cells, rays.num_beams
    R = offsets.shape[0] - 1
    W = packed.shape[1]
    C = pose_cells.shape[0]
    pf = np.zeros((R, Wmax + 1))
    totals = np.zeros(C)
    for c in range(C):
        for k in range(W):
            totals[c] += weight_of(~packed[pose_cells[c], k] & valid_mask[k], k, w)
    for r in range(R):
        c = r // B
        if totals[c] <= 0.0:
            continue
        alive = np.empty(W, np.uint64)
        for k in range(W):
            alive[k] = ~packed[pose_cells[c], k] & valid_mask[k]
        n = offsets[r + 1] - offsets[r]
        for kap in range(1, n):
            cell = cells[offsets[r] + kap]
            any_alive = False
            for k in range(W):
                hit = alive[k] & packed[cell, k]
                if hit != 0:
                    pf[r, kap] += weight_of(hit, k, w)
                    alive[k] &= ~packed[cell, k]
                if alive[k] != 0:
                    any_alive = True
            if not any_alive:
                break
        rest = 0.0
        for k in range(W):
            rest += weight_of(alive[k], k, w)
        pf[r, n] = rest
        for j in range(n + 1):
            pf[r, j] /= totals[c]
    return pf, totals


@nb.njit(cache=True)
def new_cells_kernel(samples: PackedSamples, rays: RayTable, unobserved, include_hit):
    """Per candidate ``c``: ``sum_s w_s |union_b V_b(s) & unobserved|`` over the samples with the
    candidate's cell free (module docstring; ``unobserved`` ``K`` bool, ``include_hit``: ``V_b`` includes
    the first hit), divided by ``totals[c]``, the weight of those samples: ``(out, totals)``, ``C`` float64
    each. ``seen[k]`` holds, per cell, the bit set of the samples in which some beam of the current candidate
    reaches it."""
    packed, w, valid_mask = samples.packed, samples.w, samples.valid_mask
    offsets, cells, pose_cells, B = rays.offsets, rays.cells, rays.pose_cells, rays.num_beams
    C = pose_cells.shape[0]
    W = packed.shape[1]
    K = packed.shape[0]
    out = np.zeros(C)
    totals = np.zeros(C)
    stamp = np.full(K, -1, np.int64)
    seen = np.zeros((K, W), np.uint64)
    touched = np.empty(K, np.int64)
    alive = np.empty(W, np.uint64)
    for c in range(C):
        pc = pose_cells[c]
        for k in range(W):
            totals[c] += weight_of(~packed[pc, k] & valid_mask[k], k, w)
        if totals[c] <= 0.0:
            continue
        nt = 0
        for b in range(B):
            r = c * B + b
            for k in range(W):
                alive[k] = ~packed[pc, k] & valid_mask[k]
            for j in range(offsets[r], offsets[r + 1]):
                cell = cells[j]
                any_alive = False
                for k in range(W):
                    occ = packed[cell, k]
                    vis = alive[k] if include_hit else alive[k] & ~occ
                    if unobserved[cell] and vis != 0:
                        if stamp[cell] != c:
                            stamp[cell] = c
                            for k2 in range(W):
                                seen[cell, k2] = np.uint64(0)
                            touched[nt] = cell
                            nt += 1
                        seen[cell, k] |= vis
                    alive[k] &= ~occ
                    if alive[k] != 0:
                        any_alive = True
                if not any_alive:
                    break
        acc = 0.0
        for i in range(nt):
            for k in range(W):
                acc += weight_of(seen[touched[i], k], k, w)
        out[c] = acc / totals[c]
    return out, totals
