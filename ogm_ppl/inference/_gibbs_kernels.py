"""Compiled Gibbs / Metropolis sweeps over binary maps (Sections 4.1, 4.2; Algorithms 1 and 2).

The state is the map ``m`` (uint8, ``K``) and every ray's first occupied kappa ``f`` (kept in step with
``m`` by :func:`~ogm_ppl.inference._cell_kernels.set_cell`). Random numbers come in as arrays drawn
outside (from torch's generator), so a run is reproducible from a seed and resumable from a checkpoint.

Patches are rows of a ``P x L`` int64 array (``-1`` pads patches cut by the grid edge or pinned cells).
The likelihood of each of a patch's ``W = 2^L`` configurations needs only the rays through the patch:
for each such ray the first occupied kappa outside the patch, ``f_out``, and the kappas of the patch's
cells on it; configuration ``w`` then has ``f = min(f_out, min{kappa_c : w_c = 1})``. Rays blocked before
the patch are skipped (Section 4.1.2).
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from ..priors.local import (
    STENCIL,
    patch_prior_weights,
    stencil_cell_log_odds,
    tile_candidates,
    tile_cell_log_odds,
    tile_of_anchor,
)
from ._cell_kernels import cell_log_lik_ratio, set_cell


@nb.njit(cache=True, inline="always")
def _sigmoid_draw(lo: float, u: float) -> int:
    # occupied with probability sigmoid(lo): log(u / (1 - u)) < lo  (Section 4.1.1)
    if lo == np.inf:
        return 1
    if lo == -np.inf:
        return 0
    return 1 if u * (1.0 + math.exp(-lo)) < 1.0 else 0


@nb.njit(cache=True)
def gibbs_cell_sweep(order, prior_log_odds, m, f, offsets, cells, c_off, c_ray, c_kappa, ll, uniforms):
    """One pass of single-cell Gibbs updates over ``order`` (Eq. 4.2). Returns the number of flips."""
    flips = 0
    for i in range(order.shape[0]):
        k = order[i]
        lo = prior_log_odds[k] + cell_log_lik_ratio(k, m, f, offsets, cells, c_off, c_ray, c_kappa, ll)
        v = _sigmoid_draw(lo, uniforms[i])
        if v != m[k]:
            set_cell(k, v, m, f, offsets, cells, c_off, c_ray, c_kappa)
            flips += 1
    return flips


@nb.njit(cache=True)
def metropolis_cell_sweep(order, prior_log_odds, m, f, offsets, cells, c_off, c_ray, c_kappa, ll, uniforms):
    """Metropolis-Hastings single-cell flips: propose ``m_k -> 1 - m_k`` for each proposed cell in
    ``order`` (drawn independently of the state, so the proposal is symmetric), accept with
    ``min(1, p(flipped) / p(current))``. Returns the number of accepted flips."""
    acc = 0
    for i in range(order.shape[0]):
        k = order[i]
        lo = prior_log_odds[k] + cell_log_lik_ratio(k, m, f, offsets, cells, c_off, c_ray, c_kappa, ll)
        delta = -lo if m[k] else lo  # log p(flipped) - log p(current)
        if delta >= 0.0 or (delta > -np.inf and uniforms[i] < math.exp(delta)):
            set_cell(k, 1 - m[k], m, f, offsets, cells, c_off, c_ray, c_kappa)
            acc += 1
    return acc


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


@nb.njit(cache=True)
def patch_log_lik(patch, m, f, in_patch, ray_stamp, stamp, offsets, cells, c_off, c_ray, c_kappa, ll, out):
    """``out[w] = log p(z | patch = w, rest)`` up to a constant common to all ``w`` (Eq. 4.4).

    Scratch: ``in_patch`` (bool ``K``, left all False) and ``ray_stamp`` (int64 ``R x 2``: a ray whose
    first entry equals ``stamp`` was already collected for this patch, into the slot in its second
    entry; pass a ``stamp`` never used before on every call).
    Returns ``W``.
    """
    L, n_slots, slot_ray, slot_n, ent_kappa, ent_bit = collect_patch_rays(patch, c_off, c_ray, c_kappa, ray_stamp, stamp)
    for i in range(patch.shape[0]):
        if patch[i] >= 0:
            in_patch[patch[i]] = True
    W = 1 << L
    for w in range(W):
        out[w] = 0.0
    for s in range(n_slots):
        r = slot_ray[s]
        a = offsets[r]
        n = offsets[r + 1] - a
        kmin = n
        for e in range(slot_n[s]):
            if ent_kappa[s, e] < kmin:
                kmin = ent_kappa[s, e]
        fr = f[r]
        if fr < kmin:
            continue  # blocked before the patch: every configuration sees the same f
        if fr == n:
            f_out = n
        elif in_patch[cells[a + fr]]:
            f_out = _first_outside(m, in_patch, offsets, cells, r, fr + 1)
        else:
            f_out = fr
        for w in range(W):
            fw = f_out
            for e in range(slot_n[s]):
                if (w >> ent_bit[s, e]) & 1 and ent_kappa[s, e] < fw:
                    fw = ent_kappa[s, e]
            out[w] += ll[r, fw]
    for i in range(patch.shape[0]):
        if patch[i] >= 0:
            in_patch[patch[i]] = False
    return W


@nb.njit(cache=True)
def set_patch(patch, w, m, f, offsets, cells, c_off, c_ray, c_kappa):
    bit = 0
    for i in range(patch.shape[0]):
        c = patch[i]
        if c < 0:
            continue
        set_cell(c, (w >> bit) & 1, m, f, offsets, cells, c_off, c_ray, c_kappa)
        bit += 1


@nb.njit(cache=True)
def _categorical(logw, W, u):
    mx = -np.inf
    for w in range(W):
        if logw[w] > mx:
            mx = logw[w]
    if mx == -np.inf:
        return -1
    total = 0.0
    for w in range(W):
        total += math.exp(logw[w] - mx)
    t = u * total
    acc = 0.0
    for w in range(W):
        acc += math.exp(logw[w] - mx)
        if t < acc:
            return w
    for w in range(W - 1, -1, -1):  # rounding: the last configuration with mass
        if logw[w] > -np.inf:
            return w
    return -1


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
def patch_log_weights(patch, prior_log_odds, m, f, in_patch, ray_stamp, stamp, offsets, cells, c_off,
                      c_ray, c_kappa, ll, logw):  # fmt: skip
    """Unnormalised log conditional of every configuration of ``patch`` under an independent prior."""
    W = patch_log_lik(patch, m, f, in_patch, ray_stamp, stamp, offsets, cells, c_off, c_ray, c_kappa, ll, logw)
    add_patch_prior(patch, prior_log_odds, logw, W)
    return W


@nb.njit(cache=True)
def gibbs_patch_sweep(anchors, dr, dc, rows, cols, pinned, prior_log_odds, m, f, offsets, cells, c_off,
                      c_ray, c_kappa, ll, u_choice, u_rand, u_accept, p_rand_patch, thesis_random,
                      ray_stamp, stamp0):  # fmt: skip
    """One pass of patch Gibbs updates at ``anchors`` (Algorithm 1; Algorithm 2 when
    ``p_rand_patch > 0``) with an independent cell prior. Returns the number of patches changed.

    Algorithm 2's random configuration is accepted with the Metropolis-Hastings probability
    ``min(1, p(w') / p(w))``, which keeps the posterior invariant, unless ``thesis_random`` (always
    accepted, as printed in the thesis; not exact).
    """
    K = m.shape[0]
    L = dr.shape[0]
    logw = np.empty(1 << L, np.float64)
    in_patch = np.zeros(K, np.bool_)
    patch = np.empty(L, np.int64)
    changed = 0
    for i in range(anchors.shape[0]):
        if build_patch(anchors[i, 0], anchors[i, 1], dr, dc, rows, cols, pinned, patch) == 0:
            continue
        W = patch_log_weights(patch, prior_log_odds, m, f, in_patch, ray_stamp, stamp0 + i, offsets, cells,
                              c_off, c_ray, c_kappa, ll, logw)  # fmt: skip
        cur = patch_config(patch, m)
        if p_rand_patch > 0.0 and u_rand[i] < p_rand_patch:
            prop = min(int(u_choice[i] * W), W - 1)
            if thesis_random:
                new = prop
            else:
                d = logw[prop] - logw[cur]
                new = prop if (d >= 0.0 or (d > -np.inf and u_accept[i] < math.exp(d))) else cur
        else:
            new = _categorical(logw, W, u_choice[i])
            if new < 0:
                new = cur
        if new != cur:
            set_patch(patch, new, m, f, offsets, cells, c_off, c_ray, c_kappa)
            changed += 1
    return changed


@nb.njit(cache=True)
def gibbs_cell_marginals(order, prior_log_odds, m, f, offsets, cells, c_off, c_ray, c_kappa, ll, num_sweeps, seed):
    """``num_sweeps`` systematic single-cell sweeps in one compiled call, with numba's own generator
    seeded by ``seed``; returns the running sum of the sampled maps (``K`` float64). For long runs of
    small problems (e.g. the 10^5-sweep column of Table 3.1) where one Python call per sweep would dominate.
    """
    np.random.seed(seed)
    acc = np.zeros(m.shape[0], np.float64)
    for _ in range(num_sweeps):
        for i in range(order.shape[0]):
            k = order[i]
            lo = prior_log_odds[k] + cell_log_lik_ratio(k, m, f, offsets, cells, c_off, c_ray, c_kappa, ll)
            v = _sigmoid_draw(lo, np.random.random())
            if v != m[k]:
                set_cell(k, v, m, f, offsets, cells, c_off, c_ray, c_kappa)
        for k in range(m.shape[0]):
            acc[k] += m[k]
    return acc


# ---------------------------------------------------------------------------------------------------
# Correlated priors: the prior's local conditional comes from a LocalPrior bundle (ogm_ppl.priors.local)


@nb.njit(cache=True, inline="always")
def _draw_log_odds(lo, u, cur):
    """Occupied with probability ``sigmoid(lo)`` (stable for any ``lo``). ``nan`` means both values have
    zero prior mass, so the state itself has none: any move is allowed there, and a fair coin lets the
    chain leave it."""
    if lo != lo:
        return 1 if u < 0.5 else 0
    if lo >= 0.0:
        return 1 if u * (1.0 + math.exp(-lo)) < 1.0 else 0
    e = math.exp(lo)
    return 1 if u * (1.0 + e) < e else 0


@nb.njit(cache=True)
def local_cell_sweep(order, lp, m, f, offsets, cells, c_off, c_ray, c_kappa, ll, uniforms):
    """Single-cell Gibbs (Eq. 4.2) with a correlated prior's local log-odds ``l(m_k | m_-k)``."""
    flips = 0
    for i in range(order.shape[0]):
        k = order[i]
        lo = (stencil_cell_log_odds(lp, k, m) if lp.kind == STENCIL else tile_cell_log_odds(lp, k, m))
        lo += cell_log_lik_ratio(k, m, f, offsets, cells, c_off, c_ray, c_kappa, ll)
        v = _draw_log_odds(lo, uniforms[i], m[k])
        if v != m[k]:
            set_cell(k, v, m, f, offsets, cells, c_off, c_ray, c_kappa)
            flips += 1
    return flips


@nb.njit(cache=True)
def patch_log_lik_list(patch, cands, n, m, f, in_patch, ray_stamp, stamp, offsets, cells, c_off, c_ray, c_kappa,
                       ll, out):  # fmt: skip
    """``out[j] += log p(z | patch = cands[j], rest)`` (up to a constant in ``j``); skips ``-inf`` entries.
    Bit ``b`` of a candidate is the ``b``-th live cell (as :func:`patch_log_lik`)."""
    _L, n_slots, slot_ray, slot_n, ent_kappa, ent_bit = collect_patch_rays(patch, c_off, c_ray, c_kappa, ray_stamp, stamp)
    for i in range(patch.shape[0]):
        if patch[i] >= 0:
            in_patch[patch[i]] = True
    for s in range(n_slots):
        r = slot_ray[s]
        a = offsets[r]
        nr = offsets[r + 1] - a
        kmin = nr
        for e in range(slot_n[s]):
            if ent_kappa[s, e] < kmin:
                kmin = ent_kappa[s, e]
        fr = f[r]
        if fr < kmin:
            continue
        if fr == nr:
            f_out = nr
        elif in_patch[cells[a + fr]]:
            f_out = _first_outside(m, in_patch, offsets, cells, r, fr + 1)
        else:
            f_out = fr
        for j in range(n):
            if out[j] == -np.inf:
                continue
            w = cands[j]
            fw = f_out
            for e in range(slot_n[s]):
                if (w >> ent_bit[s, e]) & 1 and ent_kappa[s, e] < fw:
                    fw = ent_kappa[s, e]
            out[j] += ll[r, fw]
    for i in range(patch.shape[0]):
        if patch[i] >= 0:
            in_patch[patch[i]] = False


@nb.njit(cache=True)
def local_patch_candidates(anchor_r, anchor_c, h, w, lp, patch, n_live, pinned, m, cands):
    """The configurations to weigh: the tile's sparse support when the patch is a tile of a table prior,
    else all ``2^n_live``. Returns the count (``-1``: the dense set does not fit in ``cands``)."""
    t = tile_of_anchor(lp, anchor_r, anchor_c, h, w)
    if t >= 0:
        return tile_candidates(lp, t, patch, pinned, m, cands)
    if n_live > 62 or (np.int64(1) << n_live) > cands.shape[0]:
        return -1
    W = np.int64(1) << n_live
    for j in range(W):
        cands[j] = j
    return W


@nb.njit(cache=True)
def local_patch_log_weights(patch, cands, n, lp, m, f, in_patch, ray_stamp, stamp, offsets, cells, c_off, c_ray,
                            c_kappa, ll, logw):  # fmt: skip
    """``logw[j]``: unnormalised log conditional of ``cands[j]`` (prior first; the likelihood only for
    candidates the prior allows)."""
    patch_prior_weights(lp, patch, m, cands, n, logw)
    patch_log_lik_list(patch, cands, n, m, f, in_patch, ray_stamp, stamp, offsets, cells, c_off, c_ray, c_kappa, ll,
                       logw)  # fmt: skip


@nb.njit(cache=True)
def local_patch_sweep(anchors, dr, dc, h, w, rows, cols, pinned, lp, m, f, offsets, cells, c_off, c_ray, c_kappa,
                      ll, u_choice, u_rand, u_accept, p_rand_patch, thesis_random, ray_stamp, stamp0, capacity):  # fmt: skip
    """Patch Gibbs (Algorithm 1; Algorithm 2 with ``p_rand_patch``) with a correlated prior.

    Each update weighs only the configurations the prior allows given the rest (a tile's sparse support
    for table priors whose tiles are the patches, else all ``2^L``), so it stays exact. Algorithm 2's
    random configuration (uniform over all ``2^L``) is accepted by Metropolis-Hastings unless
    ``thesis_random``. ``(h, w)``: the patch's rectangle (0 if not a rectangle). Returns
    ``(changed, skipped)``: patches changed, and patches whose configurations did not fit ``capacity``.
    """
    K = m.shape[0]
    L = dr.shape[0]
    cands = np.empty(capacity, np.int64)
    logw = np.empty(capacity, np.float64)
    in_patch = np.zeros(K, np.bool_)
    patch = np.empty(L, np.int64)
    pair = np.empty(2, np.int64)
    pw = np.empty(2, np.float64)
    changed = 0
    skipped = 0
    for i in range(anchors.shape[0]):
        n_live = build_patch(anchors[i, 0], anchors[i, 1], dr, dc, rows, cols, pinned, patch)
        if n_live == 0:
            continue
        cur = patch_config(patch, m)
        new = cur
        if p_rand_patch > 0.0 and u_rand[i] < p_rand_patch:
            Wl = np.int64(1) << n_live
            prop = min(np.int64(u_choice[i] * Wl), Wl - 1)
            if thesis_random:
                new = prop
            else:
                pair[0] = cur
                pair[1] = prop
                local_patch_log_weights(patch, pair, 2, lp, m, f, in_patch, ray_stamp, stamp0 + i, offsets, cells,
                                        c_off, c_ray, c_kappa, ll, pw)  # fmt: skip
                d = pw[1] - pw[0]
                if pw[0] == -np.inf or d >= 0.0 or (d > -np.inf and u_accept[i] < math.exp(d)):
                    new = prop  # (a state without mass may move anywhere)
        else:
            n = local_patch_candidates(anchors[i, 0], anchors[i, 1], h, w, lp, patch, n_live, pinned, m, cands)
            if n < 0:
                skipped += 1
                continue
            if n == 0:
                continue
            local_patch_log_weights(patch, cands, n, lp, m, f, in_patch, ray_stamp, stamp0 + i, offsets, cells,
                                    c_off, c_ray, c_kappa, ll, logw)  # fmt: skip
            j = _categorical(logw, n, u_choice[i])
            if j < 0:  # every candidate has zero mass, so has the current state: move to leave it
                j = min(np.int64(u_choice[i] * n), n - 1)
            new = cands[j]
        if new != cur:
            set_patch(patch, new, m, f, offsets, cells, c_off, c_ray, c_kappa)
            changed += 1
    return changed, skipped
