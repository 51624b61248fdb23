"""The rays through a patch and their scratch: which rays a patch update must weigh, and where
(Section 4.1.2).

The likelihood of each of a patch's ``W = 2^L`` configurations needs only the rays through the patch: for
each such ray the first occupied kappa outside the patch, ``f_out``, and the kappas of the patch's cells on
it; configuration ``w`` then has ``f = min(f_out, min{kappa_c : w_c = 1})``. Rays blocked before the patch
are skipped. :func:`collect_rays` gathers them, one *slot* per ray, into a :class:`RayScratch` that a sweep
allocates once (:func:`ray_scratch`), with the tables of
:func:`~ogm_ppl.inference._kernels.patch_lik.lik_grouped`.
"""

from __future__ import annotations

from typing import NamedTuple

import numba as nb
import numpy as np

from ogm_ppl.inference._kernels.prefetch import prefetch

GROUP_BITS = 10  # lik_grouped serves patches of at most this many cells (its tables have 2^L entries)


MAX_GROUPS = 64  # the most distinct cell masks of a patch's rays lik_grouped takes (else the per-ray paths)


class RayScratch(NamedTuple):
    """Scratch of :func:`collect_rays` and the likelihood of a patch's configurations, allocated once per
    sweep by :func:`ray_scratch` (``S`` slots: at least the rays through any one patch; ``L`` cells;
    ``W = 2^L`` when all configurations are weighed, else 1)."""

    slot_ray: np.ndarray  # S int64: the ray of each slot
    slot_fout: np.ndarray  # S int64: its first occupied kappa outside the patch (its length if none)
    slot_n: np.ndarray  # S int64: entries of the slot
    ent_kappa: np.ndarray  # S x L int64: kappas of the patch cells on the ray before slot_fout, ascending
    ent_bit: np.ndarray  # S x L int64: their bits (bit j = the j-th live cell of the patch)
    kb: np.ndarray  # L int64: kappa of each bit on the ray at hand (:func:`lik_grouped`: each entry's cell mask)
    fw: np.ndarray  # max(W, Wg) int64: the ray's first hit under each configuration (lik_grouped: sub-masks)
    lowbit: np.ndarray  # max(W, Wg) int64: index of the lowest set bit of w
    prior: np.ndarray  # W float64: log prior of each configuration (independent cells)
    ew: np.ndarray  # max(W, C) float64: exp weights of a categorical draw over up to C candidates
    fv: np.ndarray  # max(C, 2) float64: one ray's term of each candidate (:func:`lik_list`)
    g_of: np.ndarray  # 2^L int64 (empty if L > GROUP_BITS): group of each cell mask, all -1 between calls
    g_mask: np.ndarray  # G int64: the cell mask of each group (:func:`lik_grouped`)
    g_tab: np.ndarray  # G x 2^L float64 (0 x 0 if L > GROUP_BITS): each group's term of each sub-mask
    slot_g: np.ndarray  # S int64: the group of each slot
    slot_v: np.ndarray  # S x (L + 1) float64: each slot's terms at its entries, then at f_out
    ve: np.ndarray  # L + 1 float64: one ray's term with its first hit at each entry, then at f_out
    g_into: np.ndarray  # G int64: the group a group's table is folded into (-1: none; :func:`lik_grouped`)


@nb.njit(cache=True)
def ray_scratch(L, num_slots, dense, num_cands):
    """A :class:`RayScratch` for ``L``-cell patches through which at most ``num_slots`` rays pass;
    ``dense``: room for all ``2^L`` configurations."""
    Wg = (1 << L) if 0 < L <= GROUP_BITS else 0
    W = (1 << L) if dense else 1
    Wl = max(W, Wg)
    lowbit = np.zeros(Wl, np.int64)
    for w in range(1, Wl):
        b = 0
        while not (w >> b) & 1:
            b += 1
        lowbit[w] = b
    S = max(num_slots, 1)
    return RayScratch(
        np.empty(S, np.int64),
        np.empty(S, np.int64),
        np.empty(S, np.int64),
        np.empty((S, max(L, 1)), np.int64),
        np.empty((S, max(L, 1)), np.int64),
        np.empty(max(L, 1), np.int64),
        np.empty(Wl, np.int64),
        lowbit,
        np.empty(W, np.float64),
        np.empty(max(W, num_cands, 1), np.float64),
        np.empty(max(num_cands, 2), np.float64),
        np.full(Wg, -1, np.int64),
        np.empty(MAX_GROUPS if Wg else 0, np.int64),
        np.empty((MAX_GROUPS if Wg else 0, Wg), np.float64),
        np.empty(S, np.int64),
        np.empty((S if Wg else 0, L + 1), np.float64),
        np.empty(L + 1, np.float64),
        np.empty(MAX_GROUPS if Wg else 0, np.int64),
    )


@nb.njit(cache=True, inline="always")
def max_slots(L, ps):
    """An upper bound on the rays through an ``L``-cell patch: ``L`` times the largest cell degree (kept in
    the state, so that a pass over a few patches, e.g. a chromatic tile's, does not scan every cell)."""
    return min(ps.offsets.shape[0] - 1, L * ps.max_deg)


@nb.njit(cache=True)
def patch_slots(patch, c_off, num_rays):
    """The rays through ``patch`` counted with multiplicity (a bound on its slots)."""
    n = 0
    for i in range(patch.shape[0]):
        if patch[i] >= 0:
            n += c_off[patch[i] + 1] - c_off[patch[i]]
    return min(n, num_rays)


@nb.njit(cache=True)
def _first_outside(m, in_patch, offsets, cells, r, start):
    a = offsets[r]
    n = offsets[r + 1] - a
    for j in range(start, n):
        c = cells[a + j]
        if m[c] and not in_patch[c]:
            return j
    return n


@nb.njit(cache=True)
def collect_patch_rays(ps, patch, stamp):
    """The rays through a patch and, per ray (a *slot*), the (kappa, bit) of each patch cell on it.

    Returns ``(L, n_slots, slot_ray, slot_n, ent_kappa, ent_bit)``; bit ``j`` is the ``j``-th live cell.
    """
    c_off, c_ray, c_kappa, ray_stamp = ps.c_off, ps.c_ray, ps.c_kappa, ps.ray_stamp
    L = 0
    n_ent = 0
    for i in range(patch.shape[0]):
        c = patch[i]
        if c >= 0:
            L += 1
            n_ent += c_off[c + 1] - c_off[c]
    slot_ray = np.empty(n_ent, np.int64)
    slot_n = np.zeros(n_ent, np.int64)
    ent_kappa = np.empty((n_ent, max(L, 1)), np.int64)
    ent_bit = np.empty((n_ent, max(L, 1)), np.int64)
    n_slots = 0
    bit = 0
    for i in range(patch.shape[0]):
        c = patch[i]
        if c < 0:
            continue
        for p in range(c_off[c], c_off[c + 1]):
            r = c_ray[p]
            if ray_stamp[r, 0] != stamp:
                ray_stamp[r, 0] = stamp
                ray_stamp[r, 1] = n_slots
                slot_ray[n_slots] = r
                n_slots += 1
            s = ray_stamp[r, 1]
            ent_kappa[s, slot_n[s]] = c_kappa[p]
            ent_bit[s, slot_n[s]] = bit
            slot_n[s] += 1
        bit += 1
    return L, n_slots, slot_ray, slot_n, ent_kappa, ent_bit


@nb.njit(cache=True, inline="always")
def _add_entry(sc, s, kap, bit):
    """Append the patch cell ``(kappa, bit)`` to slot ``s``."""
    e = sc.slot_n[s]
    sc.ent_kappa[s, e] = kap
    sc.ent_bit[s, e] = bit
    sc.slot_n[s] = e + 1


@nb.njit(cache=True)
def collect_rays(ps, patch, stamp, sc):
    """The rays whose first hit depends on the configuration of ``patch``, into ``sc`` (Section 4.1.2).

    Per ray (a *slot*): ``f_out``, its first occupied kappa outside the patch (its length if none), and
    the (kappa, bit) of the patch cells on it before ``f_out``, ascending in kappa, so that configuration
    ``w`` has first hit ``min(f_out, first kappa whose bit is set in w)``. Rays blocked before the patch
    have no such cells and are dropped. Scratch: ``in_patch`` (bool ``K``, left all False) and
    ``ray_stamp`` (int64 ``R x 2``) of the :class:`PatchState` ``ps``; pass a ``stamp`` never used before.
    Returns the number of slots.

    A slot's entries are *all* the patch cells on its ray, so the ray's first hit ``f_r`` lies in the patch
    exactly when it equals one of their kappas; otherwise ``f_out = f_r`` (also when ``f_r = len(r)``)
    and the ray is never read. Only a ray whose first hit is a patch cell is walked on to its first
    outside hit. (Reading the cell at ``f_r`` of every ray through the patch, most of them blocked far
    before it, cost a cache miss per ray: most of a sweep on dense logs.)

    A ray is kept exactly when one of its patch cells has ``kappa <= f_r`` (if one equals ``f_r``,
    ``f_out > f_r``; else ``f_out = f_r``), so slots are opened only for those entries (first pass) and
    the kept rays' other entries added in a second pass over the same (cached) cell lists: the rays
    blocked before the patch cost one read of ``f_r`` per entry, no slot.
    """
    m, f, in_patch, ray_stamp, ll = ps.m, ps.f, ps.in_patch, ps.ray_stamp, ps.ll
    offsets, cells, c_off, c_ray, c_kappa = ps.offsets, ps.cells, ps.c_off, ps.c_ray, ps.c_kappa
    slot_ray, slot_n, slot_fout, ent_kappa, ent_bit = sc.slot_ray, sc.slot_n, sc.slot_fout, sc.ent_kappa, sc.ent_bit
    # pass 1: a slot for each ray with a patch cell at or before its first hit (the others are blocked
    # before the patch: most rays through a patch on dense logs), with those entries
    ns = 0
    bit = 0
    for i in range(patch.shape[0]):
        c = patch[i]
        if c < 0:
            continue
        for p in range(c_off[c], c_off[c + 1]):
            r = c_ray[p]
            kap = c_kappa[p]
            if kap > f[r]:
                continue
            if ray_stamp[r, 0] != stamp:
                ray_stamp[r, 0] = stamp
                ray_stamp[r, 1] = ns
                slot_ray[ns] = r
                slot_n[ns] = 0
                ns += 1
                prefetch(ll, r, kap)  # the ray's terms, read once the slots are complete
            _add_entry(sc, ray_stamp[r, 1], kap, bit)
        bit += 1
    if ns == 0:
        return 0
    # pass 2: the slots' entries after their first hit (read when that hit is a patch cell)
    bit = 0
    for i in range(patch.shape[0]):
        c = patch[i]
        if c < 0:
            continue
        for p in range(c_off[c], c_off[c + 1]):
            r = c_ray[p]
            kap = c_kappa[p]
            if kap > f[r] and ray_stamp[r, 0] == stamp:
                _add_entry(sc, ray_stamp[r, 1], kap, bit)
        bit += 1
    marked = False
    kept = 0
    for s in range(ns):
        r = slot_ray[s]
        fr = f[r]
        ne = slot_n[s]
        f_out = fr
        first = fr  # the smallest entry kappa
        for e in range(ne):
            kap = ent_kappa[s, e]
            if kap < first:
                first = kap
            if kap == fr:  # the first hit is a patch cell: walk on to the first hit outside
                if not marked:
                    for q in range(patch.shape[0]):
                        if patch[q] >= 0:
                            in_patch[patch[q]] = True
                    marked = True
                f_out = _first_outside(m, in_patch, offsets, cells, r, fr + 1)
                break
        if first >= f_out:
            continue  # blocked before the patch: every configuration sees the same first hit
        # keep the entries before f_out, insertion-sorted by kappa, in slot `kept` (<= s: in place is safe)
        k = 0
        for e in range(ne):
            kap = ent_kappa[s, e]
            if kap >= f_out:
                continue
            b = ent_bit[s, e]
            x = k
            while x > 0 and ent_kappa[kept, x - 1] > kap:
                ent_kappa[kept, x] = ent_kappa[kept, x - 1]
                ent_bit[kept, x] = ent_bit[kept, x - 1]
                x -= 1
            ent_kappa[kept, x] = kap
            ent_bit[kept, x] = b
            k += 1
        slot_ray[kept] = r
        slot_fout[kept] = f_out
        slot_n[kept] = k
        kept += 1
        prefetch(ll, r, f_out)
    if marked:
        for i in range(patch.shape[0]):
            if patch[i] >= 0:
                in_patch[patch[i]] = False
    return kept
