"""Compiled patch Gibbs sweeps over binary maps (Section 4.2; Algorithms 1 and 2), heat bath or metropolised;
the single-cell sweeps are in :mod:`~ogm_ppl.inference._kernels.cell_sweep`.

The state is a :class:`PatchState`: the map ``m`` (uint8, ``K``), every ray's first occupied kappa ``f``
(kept in step with ``m`` by :func:`set_patch`), the scratch of ray collection, and the ray index
(:class:`~ogm_ppl.raycast.RayIndex`) it walks. Random numbers come in as arrays drawn outside (from
torch's generator), so a run is reproducible from a seed and resumable from a checkpoint.

A patch is the shape ``(dr, dc)`` of a :class:`PatchGeometry` placed at an anchor (``-1`` pads cells cut
by the grid edge or pinned). The likelihood of each of a patch's ``W = 2^L`` configurations needs only the
rays through the patch: for each such ray the first occupied kappa outside the patch, ``f_out``, and the
kappas of the patch's cells on it; configuration ``w`` then has ``f = min(f_out, min{kappa_c : w_c = 1})``.
Rays blocked before the patch are skipped (Section 4.1.2).

:func:`patch_sweep` is compiled once per prior bundle type (:mod:`ogm_ppl.priors.compiled`): for priors
whose weights add over cells (independent cells) every update weighs all ``2^L`` configurations in
``O(2^L)`` per ray; for the others it weighs the candidates the prior's kind allows (a tile's sparse
support, else all ``2^L``), the rays' terms grouped by the patch cells they cross (:func:`lik_grouped`).
Both end in the one choice step of :mod:`~ogm_ppl.inference._kernels.choice`.
Sweeps allocate their scratch once (:class:`RayScratch`, :class:`~ogm_ppl.priors.compiled.scratch.TileScratch`).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba as nb
import numpy as np
from numba.extending import overload

from ogm_ppl.inference._kernels.cells import _next_occupied
from ogm_ppl.inference._kernels.choice import accept_random, categorical, categorical_table, choose, pick_from_table
from ogm_ppl.inference._kernels.prefetch import prefetch
from ogm_ppl.priors.compiled import (
    candidate_weights,
    cell_log_odds,
    kind_of,
    patch_candidates,
    scratch_capacity,
)
from ogm_ppl.priors.compiled.registry import (
    escape_proposal,
    is_additive,
    patch_allocates,
    restricted,
    shared_weights,
    shared_weights_key,
)
from ogm_ppl.priors.compiled.scratch import tile_scratch, tile_scratch_on


class PatchState(NamedTuple):
    """The map and first hits a patch sweep reads and writes, its ray-collection scratch, and the ray
    index it walks (the fields of :class:`~ogm_ppl.raycast.RayIndex`)."""

    m: np.ndarray  # K uint8: the map
    f: np.ndarray  # R int64: every ray's first occupied kappa (its length if none)
    in_patch: np.ndarray  # K bool, all False between updates
    ray_stamp: np.ndarray  # R x 2 int64: (stamp, slot) of a ray collected for the update with that stamp
    stamp: np.ndarray  # 1 int64: the next unused stamp
    offsets: np.ndarray  # R + 1 int64: CSR along rays
    cells: np.ndarray  # nnz int64
    c_off: np.ndarray  # K + 1 int64: CSR by cell
    c_ray: np.ndarray  # nnz int64
    c_kappa: np.ndarray  # nnz int64
    ll: np.ndarray  # R x (F + 1) float64
    max_deg: int  # the most rays through one cell (bounds a patch's rays: L max_deg)


def patch_state(m: np.ndarray, f: np.ndarray, index) -> PatchState:
    """The :class:`PatchState` over the map ``m`` and first hits ``f`` (views: kept in step in place)."""
    R = len(index.offsets) - 1
    return PatchState(
        m,
        f,
        np.zeros(len(m), np.bool_),
        np.full((R, 2), -1, np.int64),
        np.zeros(1, np.int64),
        index.offsets,
        index.cells,
        index.c_off,
        index.c_ray,
        index.c_kappa,
        index.ll,
        int(np.diff(index.c_off).max(initial=0)),
    )


class PatchGeometry(NamedTuple):
    """A patch shape on the grid: cell offsets ``(dr, dc)`` from the anchor, its ``h x w`` rectangle (0, 0
    if not a rectangle), the grid size and the pinned (known-free) cells."""

    dr: np.ndarray  # L int64
    dc: np.ndarray  # L int64
    h: int
    w: int
    rows: int
    cols: int
    pinned: np.ndarray  # K uint8


class PatchRule(NamedTuple):
    """How a patch update chooses: Algorithm 2's probability of a random configuration (accepted by
    Metropolis-Hastings unless ``thesis_random``), Liu's metropolised Gibbs or heat bath, the most
    candidate configurations an update may weigh, the probability of the escape move of a restricted
    candidate set (:func:`_candidate_sweep`), and ``own_factor`` (the thesis's border update of Section
    5.2.3: a tile drawn from its own table times the likelihood, the neighbouring tiles' factors
    ignored; not a Gibbs sampler of the tiled joint)."""

    p_rand_patch: float
    thesis_random: bool
    metropolised: bool
    capacity: int
    p_escape: float = 0.0
    own_factor: bool = False


GROUP_BITS = 10  # lik_grouped serves patches of at most this many cells (its tables have 2^L entries)
MAX_GROUPS = 64  # the most distinct cell masks of a patch's rays lik_grouped takes (else the per-ray paths)
GROUP_MIN_CANDS = 8  # fewer candidates go by lik_list (one pass per ray is cheaper than tables)


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


@nb.njit(cache=True)
def lik_all(sc, ns, ll, L, out):
    """``out[w] += sum_slots ll[r, f_r(w)]`` for all ``W = 2^L`` configurations of the slots of
    :func:`collect_rays`. The first hit of ``w`` follows from that of ``w`` without its lowest bit,
    ``f(w) = min(f(w & (w - 1)), kappa of the lowest bit)``, so a ray costs ``O(W)``, not ``O(W L)``."""
    W = 1 << L
    big = np.iinfo(np.int64).max
    kb = sc.kb
    fw = sc.fw
    lowbit = sc.lowbit
    for s in range(ns):
        r = sc.slot_ray[s]
        for b in range(L):
            kb[b] = big
        for e in range(sc.slot_n[s] - 1, -1, -1):  # descending, so a bit keeps its smallest kappa
            kb[sc.ent_bit[s, e]] = sc.ent_kappa[s, e]
        fo = sc.slot_fout[s]
        fw[0] = fo
        out[0] += ll[r, fo]
        for w in range(1, W):
            x = fw[w & (w - 1)]
            k = kb[lowbit[w]]
            if k < x:
                x = k
            fw[w] = x
            out[w] += ll[r, x]


@nb.njit(cache=True)
def lik_list(sc, ns, ll, cands, n, out):
    """``out[j] += sum_slots ll[r, f_r(cands[j])]`` (entries already ``-inf`` are left alone): the first
    hit of a candidate is the first entry, in kappa order, whose bit it sets (else ``f_out``).

    Per slot, the value of every candidate is set to ``ll[r, f_out]`` and then overwritten entry by entry
    in descending kappa where the candidate sets the entry's bit (so the first such entry wins): each pass
    is a branch-free loop over the candidates, and each candidate still adds the slots' terms one by one
    in slot order (the same sums, bit for bit, as reading the entries per candidate)."""
    val = sc.fv
    for s in range(ns):
        r = sc.slot_ray[s]
        vo = ll[r, sc.slot_fout[s]]
        for j in range(n):
            val[j] = vo
        for e in range(sc.slot_n[s] - 1, -1, -1):
            ve = ll[r, sc.ent_kappa[s, e]]
            b = sc.ent_bit[s, e]
            for j in range(n):
                val[j] = ve if (cands[j] >> b) & 1 else val[j]
        for j in range(n):
            o = out[j]
            out[j] = o if o == -np.inf else o + val[j]


@nb.njit(cache=True)
def lik_grouped(sc, ns, ll, cands, n, out):
    """``out[j] += sum_slots ll[r, f_r(cands[j])]``, as :func:`lik_list`, by grouping the slots by the set
    of patch cells on their ray (the *mask* ``M``: a ray's term depends on a candidate ``w`` only through
    ``w & M``). Per group a table over the sub-masks, ``T[sub] = sum_{slots} ll[r, first kappa whose bit is
    in sub, else f_out]`` (``2^|M|`` entries per slot, filled once), then per candidate one lookup a group,
    ``out[j] += sum_groups T[cands[j] & M]``: ``O(slots 2^|M| + groups n)`` against :func:`lik_list`'s
    ``O(slots n |M|)``. A group whose mask is a proper subset of another's, ``M'``, is first added into
    that table, ``T'[sub] += T[sub & M]`` (``2^|M'|`` reads), where that is cheaper than its pass over the
    candidates (``2^(|M'| + 1) <= n``). Each candidate gets the same terms as from :func:`lik_list`, summed
    in another order (equal up to rounding). Returns False, having changed nothing, when the scratch has no tables
    (patches of more than ``GROUP_BITS`` cells) or the rays have more than ``MAX_GROUPS`` masks. Entries
    already ``-inf`` stay ``-inf`` (terms are never ``+inf``)."""
    g_of, g_mask, g_tab, slot_g, ve = sc.g_of, sc.g_mask, sc.g_tab, sc.slot_g, sc.ve
    G = g_mask.shape[0]
    if g_of.shape[0] == 0:
        return False
    # the terms first, in a loop of independent loads (rows of ll far apart: cache misses that overlap)
    tv = sc.slot_v
    for s in range(ns):
        r = sc.slot_ray[s]
        for e in range(sc.slot_n[s]):
            tv[s, e] = ll[r, sc.ent_kappa[s, e]]
        tv[s, -1] = ll[r, sc.slot_fout[s]]
    ng = 0
    for s in range(ns):
        M = 0
        for e in range(sc.slot_n[s]):
            M |= np.int64(1) << sc.ent_bit[s, e]
        g = g_of[M]
        if g < 0:
            if ng == G:  # too many masks: undo
                for x in range(ng):
                    g_of[g_mask[x]] = -1
                return False
            g = ng
            ng += 1
            g_of[M] = g
            g_mask[g] = M
            sub = M
            while True:  # zero the group's sub-masks (the only entries read)
                g_tab[g, sub] = 0.0
                if sub == 0:
                    break
                sub = (sub - 1) & M
        slot_g[s] = g
    lowbit, sub_of, cell_bit = sc.lowbit, sc.fw, sc.kb
    for s in range(ns):
        g = slot_g[s]
        r = sc.slot_ray[s]
        # the slot's distinct cells in kappa order (a cell met twice counts at its first kappa), their
        # bits and terms: code c (bit e: the e-th of them is occupied) has first hit at entry lowbit(c)
        k = 0
        seen = 0
        for e in range(sc.slot_n[s]):
            b = np.int64(1) << sc.ent_bit[s, e]
            if seen & b:
                continue
            seen |= b
            ve[k] = tv[s, e]
            cell_bit[k] = b
            k += 1
        g_tab[g, 0] += tv[s, -1]
        sub_of[0] = 0
        for c in range(1, np.int64(1) << k):
            lb = lowbit[c]
            sub = sub_of[c & (c - 1)] | cell_bit[lb]
            sub_of[c] = sub
            g_tab[g, sub] += ve[lb]
    # a group whose mask lies in another's costs a pass over the candidates; folded into the table of the
    # smallest such group (when the candidates outnumber twice its sub-masks) it costs a read per sub-mask
    # instead. Smaller masks first, so that a table carries on what was folded into it.
    g_into, pop = sc.g_into, slot_g  # slot_g is spent: ng <= ns groups' popcounts
    top = 0
    for g in range(ng):
        g_into[g] = -1
        c = 0
        x = g_mask[g]
        while x:
            x &= x - 1
            c += 1
        pop[g] = c
        top = max(top, c)
    for p in range(top):
        for g in range(ng):
            if pop[g] != p:
                continue
            M = g_mask[g]
            best, best_c = -1, top + 1
            for h in range(ng):
                if pop[h] > p and pop[h] < best_c and (M & ~g_mask[h]) == 0:
                    best, best_c = h, pop[h]
            if best >= 0 and (np.int64(2) << best_c) <= n:
                H = g_mask[best]
                sub = H
                while True:
                    g_tab[best, sub] += g_tab[g, sub & M]
                    if sub == 0:
                        break
                    sub = (sub - 1) & H
                g_into[g] = best
    for g in range(ng):
        M = g_mask[g]
        if g_into[g] < 0:
            for j in range(n):
                out[j] += g_tab[g, cands[j] & M]
        g_of[M] = -1
    return True


@nb.njit(cache=True)
def patch_config(patch, m):
    w = 0
    bit = 0
    for i in range(patch.shape[0]):
        c = patch[i]
        if c < 0:
            continue
        if m[c]:
            w |= 1 << bit
        bit += 1
    return w


@nb.njit(cache=True, inline="always")
def _set_cell(ps, k, v):
    """``m[k] = v``, updating the first hits of the rays through ``k``."""
    m, f = ps.m, ps.f
    if m[k] == v:
        return
    m[k] = v
    for p in range(ps.c_off[k], ps.c_off[k + 1]):
        r = ps.c_ray[p]
        kap = ps.c_kappa[p]
        if v:
            if kap < f[r]:
                f[r] = kap
        elif f[r] == kap:
            f[r] = _next_occupied(m, ps.offsets, ps.cells, r, kap + 1)


@nb.njit(cache=True)
def set_patch(ps, patch, w):
    """Set the live cells of ``patch`` to configuration ``w`` (bit ``j``: the ``j``-th live cell)."""
    bit = 0
    for i in range(patch.shape[0]):
        c = patch[i]
        if c < 0:
            continue
        _set_cell(ps, c, (w >> bit) & 1)
        bit += 1


@nb.njit(cache=True, inline="always")
def build_patch(geo, r0, c0, patch):
    """Cells of the patch ``geo`` placed at row ``r0``, column ``c0`` (which may lie off the grid);
    ``-1`` where a cell is off the grid or pinned. Returns the number of live cells."""
    dr, dc, pinned, rows, cols = geo.dr, geo.dc, geo.pinned, geo.rows, geo.cols
    n = 0
    for j in range(dr.shape[0]):
        r = r0 + dr[j]
        c = c0 + dc[j]
        if 0 <= r < rows and 0 <= c < cols and not pinned[r * cols + c]:
            patch[j] = r * cols + c
            n += 1
        else:
            patch[j] = -1
    return n


@nb.njit(cache=True)
def build_patch_at(geo, r0, c0, patch):
    """:func:`build_patch`, callable from Python."""
    return build_patch(geo, r0, c0, patch)


@nb.njit(cache=True)
def _patch_log_lik_ws(ps, patch, stamp, out, sc):
    L = 0
    for i in range(patch.shape[0]):
        if patch[i] >= 0:
            L += 1
    W = 1 << L
    for w in range(W):
        out[w] = 0.0
    ns = collect_rays(ps, patch, stamp, sc)
    lik_all(sc, ns, ps.ll, L, out)
    return W


@nb.njit(cache=True, inline="always")
def _next_stamp(ps, n):
    """Reserve ``n`` fresh stamps; returns the first."""
    s = ps.stamp[0]
    ps.stamp[0] = s + n
    return s


@nb.njit(cache=True)
def patch_log_lik(ps, patch, out):
    """``out[w] = log p(z | patch = w, rest)`` up to a constant common to all ``w`` (Eq. 4.4). Returns ``W``."""
    sc = ray_scratch(patch.shape[0], patch_slots(patch, ps.c_off, ps.offsets.shape[0] - 1), True, 0)
    return _patch_log_lik_ws(ps, patch, _next_stamp(ps, 1), out, sc)


@nb.njit(cache=True)
def add_patch_prior(patch, prior, m, logw, W):
    """Add the cell prior (log-odds of the occupied cells) of an additive prior to every configuration."""
    for w in range(W):
        bit = 0
        for j in range(patch.shape[0]):
            c = patch[j]
            if c < 0:
                continue
            if (w >> bit) & 1:
                logw[w] += cell_log_odds(prior, c, m)
            bit += 1


@nb.njit(cache=True)
def _add_patch_prior_ws(patch, prior, m, logw, W, sc):
    """:func:`add_patch_prior` in ``O(W)``: the prior of ``w`` is that of ``w & (w - 1)`` plus the
    log-odds of its lowest bit's cell."""
    live = sc.kb
    bit = 0
    for j in range(patch.shape[0]):
        if patch[j] >= 0:
            live[bit] = patch[j]
            bit += 1
    pv = sc.prior
    pv[0] = 0.0
    for w in range(1, W):
        v = pv[w & (w - 1)] + cell_log_odds(prior, live[sc.lowbit[w]], m)
        pv[w] = v
        logw[w] += v


@nb.njit(cache=True)
def additive_patch_log_weights(ps, patch, prior, logw):
    """Unnormalised log conditional of every configuration of ``patch`` under an additive prior
    (likelihood first, then the cells' log-odds). Returns ``W``."""
    W = patch_log_lik(ps, patch, logw)
    add_patch_prior(patch, prior, ps.m, logw, W)
    return W


@nb.njit(cache=True)
def candidate_log_weights(ps, patch, prior, cands, n, logw):
    """``logw[j]``: unnormalised log conditional of ``cands[j]`` (prior first; the likelihood only for
    candidates the prior allows)."""
    sc = ray_scratch(patch.shape[0], patch_slots(patch, ps.c_off, ps.offsets.shape[0] - 1), False, n)
    ts = tile_scratch(ps.m.shape[0], scratch_capacity(prior, patch.shape[0]))
    candidate_weights(prior, patch, ps.m, cands, n, -1, logw, logw, ts)
    ns = collect_rays(ps, patch, _next_stamp(ps, 1), sc)
    lik_list(sc, ns, ps.ll, cands, n, logw)


@nb.njit(cache=True)
def _additive_sweep(ps, geo, anchors, prior, u, rule, stamp0, bit_of):
    """Patch updates that weigh all ``W = 2^L`` configurations: the likelihood through the rays of the
    patch (:func:`collect_rays`; :func:`lik_grouped` over all ``W`` codes, else :func:`lik_all`: ``O(W)``
    per ray) plus the cells' prior log-odds.
    ``stamp0``: the first of ``len(anchors)`` fresh stamps; ``bit_of`` is not read (see :func:`patch_pass`)."""
    L = geo.dr.shape[0]
    logw = np.empty(1 << L, np.float64)
    codes = np.arange(1 << L)  # every configuration, in order: the candidates of lik_grouped
    patch = np.empty(L, np.int64)
    sc = ray_scratch(L, max_slots(L, ps), True, 0)
    p_rand, thesis, metro = rule.p_rand_patch, rule.thesis_random, rule.metropolised
    changed = 0
    for i in range(anchors.shape[0]):
        n_live = build_patch(geo, anchors[i, 0], anchors[i, 1], patch)
        if n_live == 0:
            continue
        W = np.int64(1) << n_live
        for w in range(W):
            logw[w] = 0.0
        ns = collect_rays(ps, patch, stamp0 + i, sc)
        if W < GROUP_MIN_CANDS or not lik_grouped(sc, ns, ps.ll, codes, W, logw):
            lik_all(sc, ns, ps.ll, n_live, logw)
        _add_patch_prior_ws(patch, prior, ps.m, logw, W, sc)
        cur = patch_config(patch, ps.m)
        if p_rand > 0.0 and u[1, i] < p_rand:
            prop = min(int(u[0, i] * W), W - 1)
            new = prop if (thesis or accept_random(logw[cur], logw[prop], u[2, i])) else cur
        else:
            new = choose(logw, W, cur, u[0, i], u[2, i], metro, sc.ew)
            if new < 0:
                new = cur
        if new != cur:
            set_patch(ps, patch, new)
            changed += 1
    return changed, 0


@nb.njit(cache=True, inline="always")
def _add_lik(sc, ns, ll, n_live, cands, n, dense, logw):
    """Add the likelihood of the rays collected in ``sc`` to ``logw`` of the ``n`` candidates: by
    :func:`lik_grouped` for ``GROUP_MIN_CANDS`` candidates or more where it applies; else by :func:`lik_all`
    when they are the dense set (all ``2^n_live`` codes, in order) or a large share of it (scattered into
    the dense table and gathered back: each candidate adds the same terms in the same order as
    :func:`lik_list` would, so the sums are the same bit for bit), else :func:`lik_list`."""
    if n >= GROUP_MIN_CANDS and lik_grouped(sc, ns, ll, cands, n, logw):
        return
    W = np.int64(1) << n_live
    if dense and n <= sc.fw.shape[0]:
        lik_all(sc, ns, ll, n_live, logw)
    elif ns > 0 and W <= sc.prior.shape[0] and 5 * n >= 2 * W:
        dw = sc.prior
        for j in range(n):
            dw[cands[j]] = logw[j]
        lik_all(sc, ns, ll, n_live, dw)
        for j in range(n):
            logw[j] = dw[cands[j]]
    else:
        lik_list(sc, ns, ll, cands, n, logw)


@nb.njit(cache=True)
def _restricted_update(ps, patch, prior, u, i, rule, stamp, cands, n, t, cand_lp, logw, pair, pw, sc, ts):
    r"""One exact update of a patch whose candidates ``cands[:n]`` (a set ``S`` fixed by the cells outside
    the patch, e.g. the configurations a backed-off table counted after the tile's border) are only part
    of the configurations with mass (:func:`~ogm_ppl.priors.compiled.restricted`). Two steps, each
    leaving the full conditional ``pi(c) = p(c | rest, z)`` invariant:

    (A) if the current ``c`` is in ``S``: heat bath (or metropolised Gibbs) on ``S``,
        ``K_A(c, c') = pi(c') / pi(S)`` for ``c, c' in S``; else stay. Detailed balance:
        ``pi(c) K_A(c, c') = pi(c) pi(c') / pi(S)`` is symmetric, and ``K_A`` is the identity off ``S``.
    (B) with probability ``p_escape`` (the uniform ``u[3, i]``, rescaled to the proposal's uniform): an
        independence Metropolis-Hastings move, ``c' ~ q`` (:func:`~ogm_ppl.priors.compiled.escape_proposal`,
        e.g. the back-off table over all ``2^L`` configurations) accepted with
        ``min(1, pi(c') q(c) / (pi(c) q(c')))`` (``u[4, i]``): detailed balance
        ``pi(c) q(c') a(c, c') = min(pi(c) q(c'), pi(c') q(c))``.

    A mixture / composition of ``pi``-invariant kernels is ``pi``-invariant, and (B) gives every
    configuration with ``q > 0`` a positive chance in one step, so the chain is irreducible on the
    configurations with mass. ``pi`` of (B) is the kind's full prior weight (the tile's own factor
    ``pair_lp`` plus its neighbours', :func:`~ogm_ppl.priors.compiled.candidate_weights`) plus the
    likelihood of the rays through the patch, collected once for both steps. Returns whether the patch
    changed."""
    m, ll = ps.m, ps.ll
    cur = patch_config(patch, m)
    new = cur
    ns = -1
    jc = -1
    for x in range(n):
        if cands[x] == cur:
            jc = x
            break
    if jc >= 0 and n > 1:
        candidate_weights(prior, patch, m, cands, n, t, cand_lp, logw, ts)
        ns = collect_rays(ps, patch, stamp, sc)
        lik_list(sc, ns, ll, cands, n, logw)
        j = choose(logw, n, jc, u[0, i], u[2, i], rule.metropolised, sc.ew)
        if j >= 0:
            new = cands[j]
    if new != cur:
        set_patch(ps, patch, new)
    pe = rule.p_escape
    if pe > 0.0 and u[3, i] < pe:
        prop, log_q = escape_proposal(prior, t, patch, m, u[3, i] / pe, pw)
        if prop >= 0 and prop != new:
            pair[0] = new
            pair[1] = prop
            candidate_weights(prior, patch, m, pair, 2, t, pw, pw, ts)
            if ns < 0:
                ns = collect_rays(ps, patch, stamp, sc)
            lik_list(sc, ns, ll, pair, 2, pw)
            d = pw[1] - pw[0] + log_q
            if pw[0] == -np.inf or d >= 0.0 or (d > -np.inf and u[4, i] < math.exp(d)):
                set_patch(ps, patch, prop)
                new = prop
    return new != cur


@nb.njit(cache=True)
def _candidate_sweep(ps, geo, anchors, prior, u, rule, stamp0, bit_of):
    """Patch updates that weigh only the configurations the prior allows given the rest
    (:func:`~ogm_ppl.priors.compiled.patch_candidates`: a tile's sparse support for table priors whose
    tiles are the patches, else all ``2^L``), so they stay exact. A single allowed configuration is taken
    without weighing it; the weights of several are the prior's
    (:func:`~ogm_ppl.priors.compiled.candidate_weights`) plus the likelihood of the rays through the
    patch. Algorithm 2's random configuration (uniform over all ``2^L``) is accepted by
    Metropolis-Hastings unless ``thesis_random``. Returns ``(changed, skipped)``: patches changed, and
    patches whose configurations did not fit ``capacity``. ``stamp0``: the first of ``len(anchors)`` fresh
    stamps; ``bit_of``: the prior scratch's cell -> patch bit map (``K`` int64, all -1), which only the
    patch's own cells use (:func:`patch_pass`)."""
    L = geo.dr.shape[0]
    capacity = rule.capacity
    metro = rule.metropolised
    cands = np.empty(capacity, np.int64)
    cand_lp = np.empty(capacity, np.float64)
    logw = np.empty(capacity, np.float64)
    patch = np.empty(L, np.int64)
    pair = np.empty(2, np.int64)
    pw = np.empty(2, np.float64)
    sc = ray_scratch(L, max_slots(L, ps), L <= 20, capacity)
    ts = tile_scratch_on(bit_of, scratch_capacity(prior, L))
    # heat-bath updates of full tiles whose candidates and prior weights every tile of a key shares
    # (shared_weights_key): each key's candidates, weights and inverse-CDF table are built once a sweep; a
    # patch no ray reaches is a binary search (the same index as the categorical's scan), one with rays
    # starts from the key's weights instead of asking the prior again
    n_keys = 0 if metro else shared_weights(prior)
    key_n = np.full(n_keys, -1, np.int64)
    key_total = np.empty(n_keys, np.float64)
    key_last = np.empty(n_keys, np.int64)
    key_acc = np.empty((n_keys, capacity if n_keys else 0), np.float64)
    key_cands = np.empty((n_keys, capacity if n_keys else 0), np.int64)
    key_lw = np.empty((n_keys, capacity if n_keys else 0), np.float64)
    scratch = (
        cands,
        cand_lp,
        logw,
        patch,
        pair,
        pw,
        sc,
        ts,
        n_keys,
        key_n,
        key_total,
        key_last,
        key_acc,
        key_cands,
        key_lw,
    )
    return _candidate_loop(ps, geo, anchors, prior, u, rule, stamp0, scratch)


def _candidate_loop(ps, geo, anchors, prior, u, rule, stamp0, scratch):
    """Python stand-in of the loop of :func:`_candidate_sweep` for numba's overload (not called)."""
    raise NotImplementedError


def candidate_loop_of(prior):
    """The compiled loop of :func:`_candidate_sweep` for a prior bundle (or its numba type): without numba's
    runtime (:func:`_candidate_loop_lean`) when its kind registers ``patch_allocates=False``, else with it."""
    return _candidate_loop_rt if patch_allocates(prior) else _candidate_loop_lean


@overload(_candidate_loop)
def _candidate_loop_for(ps, geo, anchors, prior, u, rule, stamp0, scratch):
    run = candidate_loop_of(prior)
    return lambda ps, geo, anchors, prior, u, rule, stamp0, scratch: run(
        ps, geo, anchors, prior, u, rule, stamp0, scratch
    )


@nb.njit(cache=True, inline="always")
def _candidate_loop_body(ps, geo, anchors, prior, u, rule, stamp0, scratch):
    """The loop of :func:`_candidate_sweep` over its scratch (inlined into :func:`_candidate_loop_rt` and
    :func:`_candidate_loop_lean`)."""
    cands, cand_lp, logw, patch, pair, pw, sc, ts, n_keys, key_n, key_total, key_last, key_acc, key_cands, key_lw = (
        scratch
    )
    p_rand, thesis, metro = rule.p_rand_patch, rule.thesis_random, rule.metropolised
    ll = ps.ll
    m = ps.m
    changed = 0
    skipped = 0
    for i in range(anchors.shape[0]):
        r0 = anchors[i, 0]
        c0 = anchors[i, 1]
        n_live = build_patch(geo, r0, c0, patch)
        if n_live == 0:
            continue
        cur = patch_config(patch, m)
        new = cur
        stamp = stamp0 + i
        if p_rand > 0.0 and u[1, i] < p_rand:
            Wl = np.int64(1) << n_live
            prop = min(np.int64(u[0, i] * Wl), Wl - 1)
            if thesis:
                new = prop
            else:
                pair[0] = cur
                pair[1] = prop
                candidate_weights(prior, patch, m, pair, 2, -1, pw, pw, ts)
                ns = collect_rays(ps, patch, stamp, sc)
                lik_list(sc, ns, ll, pair, 2, pw)
                if accept_random(pw[0], pw[1], u[2, i]):
                    new = prop  # (a state without mass may move anywhere)
        else:
            ns = -1
            n = -1
            dense = False
            key = -1 if n_keys == 0 else shared_weights_key(prior, r0, c0, geo.h, geo.w, n_live)
            if key >= 0:  # a full tile whose candidates and prior weights are its key's (built once a sweep)
                ns = collect_rays(ps, patch, stamp, sc)
                if key_n[key] < 0:
                    n, t = patch_candidates(prior, r0, c0, geo.h, geo.w, patch, n_live, geo.pinned, m, cands, cand_lp)
                    if n > 1:
                        candidate_weights(prior, patch, m, cands, n, t, cand_lp, logw, ts)
                        for x in range(n):
                            key_lw[key, x] = logw[x]
                        key_total[key], key_last[key] = categorical_table(logw, n, key_acc[key])
                    if n >= 0:
                        key_n[key] = n
                        for x in range(n):
                            key_cands[key, x] = cands[x]
                    n = -1
                kn = key_n[key]
                if kn == 0:
                    continue
                if ns == 0:  # no ray reaches the patch: a draw from the key's table
                    if kn == 1 or (kn > 1 and key_total[key] > 0.0):
                        j = 0 if kn == 1 else pick_from_table(key_acc[key], key_total[key], key_last[key], kn, u[0, i])
                        new = key_cands[key, j]
                        if new != cur:
                            set_patch(ps, patch, new)
                            changed += 1
                        continue
                elif kn > 0:  # rays: the key's candidates and prior weights, then the likelihood below
                    n = kn
                    for x in range(n):
                        cands[x] = key_cands[key, x]
                        logw[x] = key_lw[key, x]
            if n < 0:
                n, t = patch_candidates(prior, r0, c0, geo.h, geo.w, patch, n_live, geo.pinned, m, cands, cand_lp)
                if n < 0:
                    skipped += 1
                    continue
                if restricted(prior, t) and not rule.own_factor:
                    if _restricted_update(
                        ps, patch, prior, u, i, rule, stamp, cands, n, t, cand_lp, logw, pair, pw, sc, ts
                    ):
                        changed += 1
                    continue
                if n == 0:
                    continue
                dense = t < 0
                if n > 1:
                    if rule.own_factor and t >= 0:  # the thesis's border update: the tile's own table only
                        for x in range(n):
                            logw[x] = cand_lp[x]
                    else:
                        candidate_weights(prior, patch, m, cands, n, t, cand_lp, logw, ts)
            if n == 1:
                j = 0  # the only configuration with mass (or, if it has none, the one to move to)
            else:
                if ns < 0:
                    ns = collect_rays(ps, patch, stamp, sc)
                _add_lik(sc, ns, ll, n_live, cands, n, dense, logw)
                jc = -1
                if metro:
                    for x in range(n):
                        if cands[x] == cur:
                            jc = x
                            break
                j = choose(logw, n, jc, u[0, i], u[2, i], metro, sc.ew)
                if j < 0:  # every candidate has zero mass, so has the current state: move to leave it,
                    # led by the data: drawn by the likelihood alone (the prior is zero for each). Any
                    # rule is exact here: the states with mass are closed under the update, so how a chain
                    # leaves a massless state does not change the posterior it samples, only how soon it
                    # gets there. (A uniform pick among the candidates filled 500 x 500 maps with noise.)
                    for x in range(n):
                        logw[x] = 0.0
                    _add_lik(sc, ns, ll, n_live, cands, n, dense, logw)
                    j = categorical(logw, n, u[0, i], sc.ew)
                    if j < 0:  # the data rule out every candidate too
                        j = min(np.int64(u[0, i] * n), n - 1)
            new = cands[j]
        if new != cur:
            set_patch(ps, patch, new)
            changed += 1
    return changed, skipped


@nb.njit(cache=True)
def _candidate_loop_rt(ps, geo, anchors, prior, u, rule, stamp0, scratch):
    """:func:`_candidate_loop_body` with numba's runtime (for patch conditionals that allocate)."""
    return _candidate_loop_body(ps, geo, anchors, prior, u, rule, stamp0, scratch)


@nb.njit(cache=True, _nrt=False)
def _candidate_loop_lean(ps, geo, anchors, prior, u, rule, stamp0, scratch):
    """:func:`_candidate_loop_body` without numba's runtime, which counts the references of every bundle
    array at each inlined call (the prior, the patch state, the scratch), a share of each patch update (as
    in :func:`~ogm_ppl.inference._kernels.cell_sweep.sweep`); only for kinds registered with
    ``patch_allocates=False``."""
    return _candidate_loop_body(ps, geo, anchors, prior, u, rule, stamp0, scratch)


def _patch_pass(ps, geo, anchors, prior, u, rule, stamp0, bit_of):
    """Python stand-in of :func:`patch_pass` for numba's overload (not called)."""
    raise NotImplementedError


@overload(_patch_pass)
def _patch_pass_for(ps, geo, anchors, prior, u, rule, stamp0, bit_of):
    if kind_of(prior).additive:
        return lambda ps, geo, anchors, prior, u, rule, stamp0, bit_of: _additive_sweep(
            ps, geo, anchors, prior, u, rule, stamp0, bit_of
        )
    return lambda ps, geo, anchors, prior, u, rule, stamp0, bit_of: _candidate_sweep(
        ps, geo, anchors, prior, u, rule, stamp0, bit_of
    )


@nb.njit(cache=True)
def patch_pass(ps, geo, anchors, prior, u, rule, stamp0, bit_of):
    """:func:`patch_sweep` with its stamps (``stamp0 .. stamp0 + len(anchors) - 1``, reserved by the caller)
    and the prior scratch's ``bit_of`` (``K`` int64, all -1) given: the building block of the chromatic
    patch sweeps, whose tiles of one colour run it at once (every array it writes is indexed by the patch's
    cells or its rays, so disjoint between tiles; :mod:`~ogm_ppl.inference._kernels.parallel_patch`)."""
    return _patch_pass(ps, geo, anchors, prior, u, rule, stamp0, bit_of)


@nb.njit(cache=True)
def patch_sweep(ps, geo, anchors, prior, u, rule):
    """One pass of patch updates at ``anchors`` (``n x 2``; Algorithm 1, Algorithm 2 when
    ``rule.p_rand_patch > 0``) with the uniforms ``u`` (``3 x n``: choice, random-patch, acceptance), the
    loop chosen by the prior bundle's type when it compiles. Returns ``(changed, skipped)``."""
    bit_of = np.full(0 if is_additive(prior) else ps.m.shape[0], -1, np.int64)
    return _patch_pass(ps, geo, anchors, prior, u, rule, _next_stamp(ps, anchors.shape[0]), bit_of)


def _patch_log_weights(ps, patch, prior, logw):
    raise NotImplementedError


@overload(_patch_log_weights)
def _patch_log_weights_for(ps, patch, prior, logw):
    if kind_of(prior).additive:
        return lambda ps, patch, prior, logw: additive_patch_log_weights(ps, patch, prior, logw)

    def impl(ps, patch, prior, logw):
        W = logw.shape[0]
        cands = np.arange(W)
        candidate_log_weights(ps, patch, prior, cands, W, logw)
        return W

    return impl


@nb.njit(cache=True)
def patch_log_weights(ps, patch, prior, logw):
    """``logw[w]``: unnormalised log conditional of every configuration of ``patch`` (``logw``: at least
    ``2^L`` for additive priors, exactly ``2^L`` for the others). Returns ``W``."""
    return _patch_log_weights(ps, patch, prior, logw)
