"""Compiled patch Gibbs sweeps over binary maps (Section 4.2; Algorithms 1 and 2), heat bath or metropolised;
the single-cell sweeps are in :mod:`~ogm_ppl.inference._kernels.cell_sweep`.

The state is the map ``m`` (uint8, ``K``) and every ray's first occupied kappa ``f`` (kept in step with
``m`` by :func:`~ogm_ppl.inference._kernels.cells.set_cell`). Random numbers come in as arrays drawn
outside (from torch's generator), so a run is reproducible from a seed and resumable from a checkpoint.

Patches are rows of a ``P x L`` int64 array (``-1`` pads patches cut by the grid edge or pinned cells).
The likelihood of each of a patch's ``W = 2^L`` configurations needs only the rays through the patch:
for each such ray the first occupied kappa outside the patch, ``f_out``, and the kappas of the patch's
cells on it; configuration ``w`` then has ``f = min(f_out, min{kappa_c : w_c = 1})``. Rays blocked before
the patch are skipped (Section 4.1.2).

Sweeps allocate their scratch once (:class:`RayScratch`, :class:`~ogm_ppl.priors.local.TileScratch`);
the public one-patch functions (``patch_log_lik``, ``local_patch_log_weights``) allocate their own.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba as nb
import numpy as np

from ogm_ppl.inference._kernels.cells import set_cell
from ogm_ppl.priors.local import (
    patch_prior_weights_ws,
    tile_candidates,
    tile_of_anchor,
    tile_patch_factors,
    tile_patch_setup,
    tile_scratch,
)


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
def collect_patch_rays(patch, c_off, c_ray, c_kappa, ray_stamp, stamp):
    """The rays through a patch and, per ray (a *slot*), the (kappa, bit) of each patch cell on it.

    Returns ``(L, n_slots, slot_ray, slot_n, ent_kappa, ent_bit)``; bit ``j`` is the ``j``-th live cell.
    """
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


class RayScratch(NamedTuple):
    """Scratch of :func:`collect_rays` and the likelihood of a patch's configurations, allocated once per
    sweep by :func:`ray_scratch` (``S`` slots: at least the rays through any one patch; ``L`` cells;
    ``W = 2^L`` when all configurations are weighed, else 1)."""

    slot_ray: np.ndarray  # S int64: the ray of each slot
    slot_fout: np.ndarray  # S int64: its first occupied kappa outside the patch (its length if none)
    slot_n: np.ndarray  # S int64: entries of the slot
    ent_kappa: np.ndarray  # S x L int64: kappas of the patch cells on the ray before slot_fout, ascending
    ent_bit: np.ndarray  # S x L int64: their bits (bit j = the j-th live cell of the patch)
    kb: np.ndarray  # L int64: kappa of each bit on the ray at hand
    fw: np.ndarray  # W int64: the ray's first hit under each configuration
    lowbit: np.ndarray  # W int64: index of the lowest set bit of w
    prior: np.ndarray  # W float64: log prior of each configuration (independent cells)
    ew: np.ndarray  # max(W, C) float64: exp weights of a categorical draw over up to C candidates


@nb.njit(cache=True)
def ray_scratch(L, num_slots, dense, num_cands):
    """A :class:`RayScratch` for ``L``-cell patches through which at most ``num_slots`` rays pass;
    ``dense``: room for all ``2^L`` configurations."""
    W = (1 << L) if dense else 1
    lowbit = np.zeros(W, np.int64)
    for w in range(1, W):
        b = 0
        while not (w >> b) & 1:
            b += 1
        lowbit[w] = b
    S = max(num_slots, 1)
    return RayScratch(np.empty(S, np.int64), np.empty(S, np.int64), np.empty(S, np.int64),
                      np.empty((S, max(L, 1)), np.int64), np.empty((S, max(L, 1)), np.int64),
                      np.empty(max(L, 1), np.int64), np.empty(W, np.int64), lowbit, np.empty(W, np.float64),
                      np.empty(max(W, num_cands, 1), np.float64))  # fmt: skip


@nb.njit(cache=True)
def max_slots(L, c_off, num_rays):
    """An upper bound on the rays through an ``L``-cell patch: ``L`` times the largest cell degree."""
    deg = 0
    for k in range(c_off.shape[0] - 1):
        d = c_off[k + 1] - c_off[k]
        if d > deg:
            deg = d
    return min(num_rays, L * deg)


@nb.njit(cache=True)
def patch_slots(patch, c_off, num_rays):
    """The rays through ``patch`` counted with multiplicity (a bound on its slots)."""
    n = 0
    for i in range(patch.shape[0]):
        if patch[i] >= 0:
            n += c_off[patch[i] + 1] - c_off[patch[i]]
    return min(n, num_rays)


@nb.njit(cache=True)
def collect_rays(patch, m, f, in_patch, ray_stamp, stamp, offsets, cells, c_off, c_ray, c_kappa, sc):
    """The rays whose first hit depends on the configuration of ``patch``, into ``sc`` (Section 4.1.2).

    Per ray (a *slot*): ``f_out``, its first occupied kappa outside the patch (its length if none), and
    the (kappa, bit) of the patch cells on it before ``f_out``, ascending in kappa, so that configuration
    ``w`` has first hit ``min(f_out, first kappa whose bit is set in w)``. Rays blocked before the patch
    have no such cells and are dropped. Scratch: ``in_patch`` (bool ``K``, left all False) and
    ``ray_stamp`` (int64 ``R x 2``; pass a ``stamp`` never used before). Returns the number of slots.
    """
    ns = 0
    bit = 0
    for i in range(patch.shape[0]):
        c = patch[i]
        if c < 0:
            continue
        in_patch[c] = True
        for p in range(c_off[c], c_off[c + 1]):
            r = c_ray[p]
            if ray_stamp[r, 0] != stamp:
                ray_stamp[r, 0] = stamp
                ray_stamp[r, 1] = ns
                sc.slot_ray[ns] = r
                sc.slot_n[ns] = 0
                ns += 1
            s = ray_stamp[r, 1]
            e = sc.slot_n[s]
            sc.ent_kappa[s, e] = c_kappa[p]
            sc.ent_bit[s, e] = bit
            sc.slot_n[s] = e + 1
        bit += 1
    kept = 0
    for s in range(ns):
        r = sc.slot_ray[s]
        a = offsets[r]
        n = offsets[r + 1] - a
        fr = f[r]
        if fr == n:
            f_out = n
        elif in_patch[cells[a + fr]]:
            f_out = _first_outside(m, in_patch, offsets, cells, r, fr + 1)
        else:
            f_out = fr
        # keep the entries before f_out, insertion-sorted by kappa, in slot `kept` (<= s: in place is safe)
        k = 0
        for e in range(sc.slot_n[s]):
            kap = sc.ent_kappa[s, e]
            if kap >= f_out:
                continue
            b = sc.ent_bit[s, e]
            x = k
            while x > 0 and sc.ent_kappa[kept, x - 1] > kap:
                sc.ent_kappa[kept, x] = sc.ent_kappa[kept, x - 1]
                sc.ent_bit[kept, x] = sc.ent_bit[kept, x - 1]
                x -= 1
            sc.ent_kappa[kept, x] = kap
            sc.ent_bit[kept, x] = b
            k += 1
        if k == 0:
            continue  # every configuration sees the same first hit
        sc.slot_ray[kept] = r
        sc.slot_fout[kept] = f_out
        sc.slot_n[kept] = k
        kept += 1
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
    """``out[j] += sum_slots ll[r, f_r(cands[j])]`` (entries already ``-inf`` are skipped): the first
    hit of a candidate is the first entry, in kappa order, whose bit it sets (else ``f_out``)."""
    for s in range(ns):
        r = sc.slot_ray[s]
        fo = sc.slot_fout[s]
        ne = sc.slot_n[s]
        for j in range(n):
            if out[j] == -np.inf:
                continue
            w = cands[j]
            fw = fo
            for e in range(ne):
                if (w >> sc.ent_bit[s, e]) & 1:
                    fw = sc.ent_kappa[s, e]
                    break
            out[j] += ll[r, fw]


@nb.njit(cache=True)
def _patch_log_lik_ws(patch, m, f, in_patch, ray_stamp, stamp, offsets, cells, c_off, c_ray, c_kappa, ll, out, sc):
    L = 0
    for i in range(patch.shape[0]):
        if patch[i] >= 0:
            L += 1
    W = 1 << L
    for w in range(W):
        out[w] = 0.0
    ns = collect_rays(patch, m, f, in_patch, ray_stamp, stamp, offsets, cells, c_off, c_ray, c_kappa, sc)
    lik_all(sc, ns, ll, L, out)
    return W


@nb.njit(cache=True)
def patch_log_lik(patch, m, f, in_patch, ray_stamp, stamp, offsets, cells, c_off, c_ray, c_kappa, ll, out):
    """``out[w] = log p(z | patch = w, rest)`` up to a constant common to all ``w`` (Eq. 4.4).

    Scratch: ``in_patch`` (bool ``K``, left all False) and ``ray_stamp`` (int64 ``R x 2``: a ray whose
    first entry equals ``stamp`` was already collected for this patch, into the slot in its second
    entry; pass a ``stamp`` never used before on every call).
    Returns ``W``.
    """
    L = patch.shape[0]
    sc = ray_scratch(L, patch_slots(patch, c_off, offsets.shape[0] - 1), True, 0)
    return _patch_log_lik_ws(patch, m, f, in_patch, ray_stamp, stamp, offsets, cells, c_off, c_ray, c_kappa, ll,
                             out, sc)  # fmt: skip


@nb.njit(cache=True)
def set_patch(patch, w, m, f, offsets, cells, c_off, c_ray, c_kappa):
    bit = 0
    for i in range(patch.shape[0]):
        c = patch[i]
        if c < 0:
            continue
        set_cell(c, (w >> bit) & 1, m, f, offsets, cells, c_off, c_ray, c_kappa)
        bit += 1


@nb.njit(cache=True, inline="always")
def _exp_weights(logw, n, ew, skip):
    """``ew[j] = exp(logw[j] - max logw)`` for ``j < n``; returns ``(sum, sum without entry skip)``, each
    summed directly (no cancellation), or ``(-1, -1)`` if no entry has mass."""
    mx = -np.inf
    for j in range(n):
        if logw[j] > mx:
            mx = logw[j]
    if mx == -np.inf:
        return -1.0, -1.0
    total = 0.0
    other = 0.0
    for j in range(n):
        e = math.exp(logw[j] - mx)
        ew[j] = e
        total += e
        if j != skip:
            other += e
    return total, other


@nb.njit(cache=True)
def _categorical_ws(logw, W, u, ew):
    """Index drawn by inverse CDF from ``softmax(logw[:W])`` with the uniform ``u`` (``-1`` if no entry
    has mass); ``ew`` (``>= W``) holds the exponentials, so each is computed once."""
    total, _ = _exp_weights(logw, W, ew, -1)
    if total < 0.0:
        return -1
    t = u * total
    acc = 0.0
    for w in range(W):
        acc += ew[w]
        if t < acc:
            return w
    for w in range(W - 1, -1, -1):  # rounding: the last configuration with mass
        if logw[w] > -np.inf:
            return w
    return -1


@nb.njit(cache=True)
def metropolised_pick(logw, n, jc, u_choice, u_accept, ew):
    """Liu's metropolised Gibbs over ``n`` candidates with the current one at index ``jc``: propose
    ``j != jc`` with probability ``p_j / (1 - p_jc)`` and accept with ``min(1, (1 - p_jc) / (1 - p_j))``,
    which leaves ``p`` invariant and moves at least as often as a heat-bath draw (Peskun's order).

    ``p = softmax(logw[:n])``; ``jc = -1`` (the current configuration is not a candidate: it has no prior
    mass) falls back to a heat-bath draw. Returns the chosen index (``jc`` when staying; ``-1`` if no
    candidate has mass). ``ew`` (``>= n``) is scratch.
    """
    if jc < 0:
        return _categorical_ws(logw, n, u_choice, ew)
    total, other = _exp_weights(logw, n, ew, jc)
    if total < 0.0:
        return -1
    if other == 0.0:
        return jc  # no other configuration has mass
    t = u_choice * other
    acc = 0.0
    pick = -1
    for j in range(n):
        if j == jc or ew[j] == 0.0:
            continue
        pick = j  # (rounding: the last one with mass)
        acc += ew[j]
        if t < acc:
            break
    denom = other + ew[jc] - ew[pick]  # = total - e_pick, so the ratio is (1 - p_jc) / (1 - p_pick)
    if denom <= 0.0 or u_accept * denom < other:
        return pick
    return jc


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
def build_patch(r0, c0, dr, dc, rows, cols, pinned, patch):
    """Cells of the patch of shape ``(dr, dc)`` placed at row ``r0``, column ``c0`` (which may lie off the
    grid); ``-1`` where a cell is off the grid or pinned. Returns the number of live cells."""
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
def add_patch_prior(patch, prior_log_odds, logw, W):
    """Add the independent cell prior (log-odds of the occupied cells) to every configuration's weight."""
    for w in range(W):
        bit = 0
        for j in range(patch.shape[0]):
            c = patch[j]
            if c < 0:
                continue
            if (w >> bit) & 1:
                logw[w] += prior_log_odds[c]
            bit += 1


@nb.njit(cache=True)
def _add_patch_prior_ws(patch, prior_log_odds, logw, W, sc):
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
        v = pv[w & (w - 1)] + prior_log_odds[live[sc.lowbit[w]]]
        pv[w] = v
        logw[w] += v


@nb.njit(cache=True)
def patch_log_weights(patch, prior_log_odds, m, f, in_patch, ray_stamp, stamp, offsets, cells, c_off,
                      c_ray, c_kappa, ll, logw):  # fmt: skip
    """Unnormalised log conditional of every configuration of ``patch`` under an independent prior."""
    W = patch_log_lik(patch, m, f, in_patch, ray_stamp, stamp, offsets, cells, c_off, c_ray, c_kappa, ll, logw)
    add_patch_prior(patch, prior_log_odds, logw, W)
    return W


@nb.njit(cache=True)
def gibbs_patch_sweep(anchors, dr, dc, rows, cols, pinned, prior_log_odds, m, f, offsets, cells, c_off,
                      c_ray, c_kappa, ll, u_choice, u_rand, u_accept, p_rand_patch, thesis_random,
                      ray_stamp, stamp0, metropolised):  # fmt: skip
    """One pass of patch Gibbs updates at ``anchors`` (Algorithm 1; Algorithm 2 when
    ``p_rand_patch > 0``) with an independent cell prior. Returns the number of patches changed.

    Each update weighs all ``W = 2^L`` configurations: the likelihood through the rays of the patch
    (:func:`collect_rays`, :func:`lik_all`: ``O(W)`` per ray) plus the cells' prior log-odds.
    Algorithm 2's random configuration is accepted with the Metropolis-Hastings probability
    ``min(1, p(w') / p(w))``, which keeps the posterior invariant, unless ``thesis_random`` (always
    accepted, as printed in the thesis; not exact). ``metropolised``: the other updates are Liu's
    metropolised Gibbs (:func:`metropolised_pick`) instead of heat-bath draws.
    """
    K = m.shape[0]
    L = dr.shape[0]
    logw = np.empty(1 << L, np.float64)
    in_patch = np.zeros(K, np.bool_)
    patch = np.empty(L, np.int64)
    sc = ray_scratch(L, max_slots(L, c_off, offsets.shape[0] - 1), True, 0)
    changed = 0
    for i in range(anchors.shape[0]):
        if build_patch(anchors[i, 0], anchors[i, 1], dr, dc, rows, cols, pinned, patch) == 0:
            continue
        W = _patch_log_lik_ws(patch, m, f, in_patch, ray_stamp, stamp0 + i, offsets, cells, c_off, c_ray,
                              c_kappa, ll, logw, sc)  # fmt: skip
        _add_patch_prior_ws(patch, prior_log_odds, logw, W, sc)
        cur = patch_config(patch, m)
        if p_rand_patch > 0.0 and u_rand[i] < p_rand_patch:
            prop = min(int(u_choice[i] * W), W - 1)
            if thesis_random:
                new = prop
            else:
                d = logw[prop] - logw[cur]
                new = prop if (d >= 0.0 or (d > -np.inf and u_accept[i] < math.exp(d))) else cur
        elif metropolised:
            new = metropolised_pick(logw, W, cur, u_choice[i], u_accept[i], sc.ew)
            if new < 0:
                new = cur
        else:
            new = _categorical_ws(logw, W, u_choice[i], sc.ew)
            if new < 0:
                new = cur
        if new != cur:
            set_patch(patch, new, m, f, offsets, cells, c_off, c_ray, c_kappa)
            changed += 1
    return changed


# ---------------------------------------------------------------------------------------------------
# Correlated priors: the prior's local conditional comes from a LocalPrior bundle (ogm_ppl.priors.local)


@nb.njit(cache=True)
def patch_log_lik_list(patch, cands, n, m, f, in_patch, ray_stamp, stamp, offsets, cells, c_off, c_ray, c_kappa,
                       ll, out):  # fmt: skip
    """``out[j] += log p(z | patch = cands[j], rest)`` (up to a constant in ``j``); skips ``-inf`` entries.
    Bit ``b`` of a candidate is the ``b``-th live cell (as :func:`patch_log_lik`)."""
    sc = ray_scratch(patch.shape[0], patch_slots(patch, c_off, offsets.shape[0] - 1), False, 0)
    ns = collect_rays(patch, m, f, in_patch, ray_stamp, stamp, offsets, cells, c_off, c_ray, c_kappa, sc)
    lik_list(sc, ns, ll, cands, n, out)


@nb.njit(cache=True, inline="always")
def local_patch_candidates(anchor_r, anchor_c, h, w, lp, patch, n_live, pinned, m, cands, cand_lp):
    """The configurations to weigh: the tile's sparse support when the patch is a tile of a table prior
    (with the tile's own log factor of each in ``cand_lp``), else all ``2^n_live``. Returns ``(count,
    tile)``: count ``-1`` when the dense set does not fit in ``cands``; tile ``-1`` when not a tile."""
    t = tile_of_anchor(lp, anchor_r, anchor_c, h, w)
    if t >= 0:
        return tile_candidates(lp, t, patch, pinned, m, cands, cand_lp), t
    if n_live > 62 or (np.int64(1) << n_live) > cands.shape[0]:
        return -1, t
    W = np.int64(1) << n_live
    for j in range(W):
        cands[j] = j
    return W, t


@nb.njit(cache=True)
def _local_patch_log_weights_ws(patch, cands, n, lp, m, f, in_patch, ray_stamp, stamp, offsets, cells, c_off,
                                c_ray, c_kappa, ll, logw, sc, ts):  # fmt: skip
    patch_prior_weights_ws(lp, patch, m, cands, n, logw, ts)
    ns = collect_rays(patch, m, f, in_patch, ray_stamp, stamp, offsets, cells, c_off, c_ray, c_kappa, sc)
    lik_list(sc, ns, ll, cands, n, logw)


@nb.njit(cache=True)
def local_patch_log_weights(patch, cands, n, lp, m, f, in_patch, ray_stamp, stamp, offsets, cells, c_off, c_ray,
                            c_kappa, ll, logw):  # fmt: skip
    """``logw[j]``: unnormalised log conditional of ``cands[j]`` (prior first; the likelihood only for
    candidates the prior allows)."""
    sc = ray_scratch(patch.shape[0], patch_slots(patch, c_off, offsets.shape[0] - 1), False, 0)
    ts = tile_scratch(lp, m.shape[0], patch.shape[0])
    _local_patch_log_weights_ws(patch, cands, n, lp, m, f, in_patch, ray_stamp, stamp, offsets, cells, c_off,
                                c_ray, c_kappa, ll, logw, sc, ts)  # fmt: skip


@nb.njit(cache=True, inline="always")
def _add_lik(sc, ns, ll, n_live, cands, n, dense, logw):
    """Add the likelihood of the rays collected in ``sc`` to ``logw`` of the ``n`` candidates: by
    :func:`lik_all` when they are the dense set (all ``2^n_live`` codes, in order), else :func:`lik_list`."""
    if dense and n <= sc.fw.shape[0]:
        lik_all(sc, ns, ll, n_live, logw)
    else:
        lik_list(sc, ns, ll, cands, n, logw)


@nb.njit(cache=True)
def local_patch_sweep(anchors, dr, dc, h, w, rows, cols, pinned, lp, m, f, offsets, cells, c_off, c_ray, c_kappa,
                      ll, u_choice, u_rand, u_accept, p_rand_patch, thesis_random, ray_stamp, stamp0, capacity,
                      metropolised):  # fmt: skip
    """Patch Gibbs (Algorithm 1; Algorithm 2 with ``p_rand_patch``) with a correlated prior.

    Each update weighs only the configurations the prior allows given the rest (a tile's sparse support
    for table priors whose tiles are the patches, else all ``2^L``), so it stays exact. For a tile, a
    single allowed configuration is drawn without weighing it, and the weights of several are the
    tile's own factor (read with the candidates) plus the factors of the neighbouring tiles whose
    windows hold patch cells (:func:`~ogm_ppl.priors.local.tile_patch_factors`) plus the likelihood of
    the rays through the patch. Algorithm 2's random configuration (uniform over all ``2^L``) is
    accepted by Metropolis-Hastings unless ``thesis_random``. ``(h, w)``: the patch's rectangle (0 if
    not a rectangle). ``metropolised``: Liu's metropolised Gibbs over the candidates instead of a
    heat-bath draw. Returns ``(changed, skipped)``: patches changed, and patches whose configurations
    did not fit ``capacity``.
    """
    K = m.shape[0]
    L = dr.shape[0]
    cands = np.empty(capacity, np.int64)
    cand_lp = np.empty(capacity, np.float64)
    logw = np.empty(capacity, np.float64)
    in_patch = np.zeros(K, np.bool_)
    patch = np.empty(L, np.int64)
    pair = np.empty(2, np.int64)
    pw = np.empty(2, np.float64)
    sc = ray_scratch(L, max_slots(L, c_off, offsets.shape[0] - 1), L <= 20, capacity)
    ts = tile_scratch(lp, K, L)
    changed = 0
    skipped = 0
    for i in range(anchors.shape[0]):
        n_live = build_patch(anchors[i, 0], anchors[i, 1], dr, dc, rows, cols, pinned, patch)
        if n_live == 0:
            continue
        cur = patch_config(patch, m)
        new = cur
        stamp = stamp0 + i
        if p_rand_patch > 0.0 and u_rand[i] < p_rand_patch:
            Wl = np.int64(1) << n_live
            prop = min(np.int64(u_choice[i] * Wl), Wl - 1)
            if thesis_random:
                new = prop
            else:
                pair[0] = cur
                pair[1] = prop
                _local_patch_log_weights_ws(patch, pair, 2, lp, m, f, in_patch, ray_stamp, stamp, offsets, cells,
                                            c_off, c_ray, c_kappa, ll, pw, sc, ts)  # fmt: skip
                d = pw[1] - pw[0]
                if pw[0] == -np.inf or d >= 0.0 or (d > -np.inf and u_accept[i] < math.exp(d)):
                    new = prop  # (a state without mass may move anywhere)
        else:
            n, t = local_patch_candidates(anchors[i, 0], anchors[i, 1], h, w, lp, patch, n_live, pinned, m, cands,
                                          cand_lp)  # fmt: skip
            if n < 0:
                skipped += 1
                continue
            if n == 0:
                continue
            if n == 1:
                j = 0  # the only configuration with mass (or, if it has none, the one to move to)
            else:
                if t >= 0:  # the tile's own factor came with the candidates; add its neighbours'
                    for j in range(n):
                        logw[j] = cand_lp[j]
                    nt = tile_patch_setup(lp, patch, m, t, ts)
                    tile_patch_factors(lp, nt, ts, cands, n, logw)
                else:
                    patch_prior_weights_ws(lp, patch, m, cands, n, logw, ts)
                ns = collect_rays(patch, m, f, in_patch, ray_stamp, stamp, offsets, cells, c_off, c_ray, c_kappa, sc)
                _add_lik(sc, ns, ll, n_live, cands, n, t < 0, logw)
                if metropolised:
                    jc = -1
                    for x in range(n):
                        if cands[x] == cur:
                            jc = x
                            break
                    j = metropolised_pick(logw, n, jc, u_choice[i], u_accept[i], sc.ew)
                else:
                    j = _categorical_ws(logw, n, u_choice[i], sc.ew)
                if j < 0:  # every candidate has zero mass, so has the current state: move to leave it,
                    # led by the data: drawn by the likelihood alone (the prior is zero for each). Any
                    # rule is exact here: the states with mass are closed under the update, so how a chain
                    # leaves a massless state does not change the posterior it samples, only how soon it
                    # gets there. (A uniform pick among the candidates filled 500 x 500 maps with noise.)
                    for x in range(n):
                        logw[x] = 0.0
                    _add_lik(sc, ns, ll, n_live, cands, n, t < 0, logw)
                    j = _categorical_ws(logw, n, u_choice[i], sc.ew)
                    if j < 0:  # the data rule out every candidate too
                        j = min(np.int64(u_choice[i] * n), n - 1)
            new = cands[j]
        if new != cur:
            set_patch(patch, new, m, f, offsets, cells, c_off, c_ray, c_kappa)
            changed += 1
    return changed, skipped
