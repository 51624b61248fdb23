"""The likelihood of a patch's configurations from the rays collected through it (Eq. 4.4).

Given the slots of :func:`~ogm_ppl.inference._kernels.patch_rays.collect_rays` (per ray ``f_out`` and the
patch cells on it in kappa order), configuration ``w`` sees the first hit ``min(f_out, min{kappa_c : w_c =
1})`` and adds the ray's term ``ll[r, f]``. Three ways to sum these terms: over all ``2^L`` configurations
in ``O(2^L)`` per ray (:func:`lik_all`), over a list of candidates (:func:`lik_list`), or by grouping the
rays by the patch cells they cross (:func:`lik_grouped`); :func:`_add_lik` picks one.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from ogm_ppl.inference._kernels.patch_rays import collect_rays, patch_slots, ray_scratch
from ogm_ppl.inference._kernels.patch_state import _next_stamp

GROUP_MIN_CANDS = 8  # fewer candidates go by lik_list (one pass per ray is cheaper than tables)


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
def _patch_log_lik_ws(ps, patch, stamp, out, sc):
    L = 0
    for i in range(patch.shape[0]):
        if patch[i] >= 0:
            L += 1
    W = 1 << L
    for w in range(W):
        out[w] = 0.0
    ns = collect_rays(ps, patch, stamp, sc)
    lik_all(sc, ns, ps.ll, np.int64(L), out)  # int64: no extra compile for the literal L = 0
    return W


@nb.njit(cache=True)
def patch_log_lik(ps, patch, out):
    """``out[w] = log p(z | patch = w, rest)`` up to a constant common to all ``w`` (Eq. 4.4). Returns ``W``."""
    sc = ray_scratch(patch.shape[0], patch_slots(patch, ps.c_off, ps.offsets.shape[0] - 1), np.bool_(True), np.int64(0))
    return _patch_log_lik_ws(ps, patch, _next_stamp(ps, 1), out, sc)
