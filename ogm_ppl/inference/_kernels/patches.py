"""Compiled patch-map updates (Chapter 3): the log weight of every configuration of a patch.

Three ways to weigh a patch's ``W = 2^L`` configurations against the readings through it:

* ``OFFLINE`` (Eq. 3.3): cells outside the patch come from a reference map; the first occupied cell of
  each ray is then determined by the configuration (shared with patch Gibbs).
* ``ONLINE`` (Eq. 3.1, forward model): cells outside the patch are not known; each reading's likelihood
  marginalises them under the independent cell prior, ``p(z_n | a_w) = sum_f p(z_n | f) p(f | a_w)``.
  With ``L = 1`` this is Elfes's exact single-reading update.
* ``INVERSE`` (Eq. 3.2): the patch inverse sensor model, total mass ``p_match`` on the configurations that
  match the reading (patch cells on the ray free before its cell, occupied at it; cells beyond free to be
  anything), the rest shared by the others. With ``L = 1`` this is Moravec's term with
  ``l_occ = -l_free = logit(p_match)``.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from ogm_ppl.inference._kernels.gibbs import add_patch_prior, collect_patch_rays, patch_log_weights

OFFLINE, ONLINE, INVERSE = 0, 1, 2


@nb.njit(cache=True, inline="always")
def _logaddexp(a, b):
    if a == -np.inf:
        return b
    if b == -np.inf:
        return a
    if a > b:
        return a + math.log1p(math.exp(b - a))
    return b + math.log1p(math.exp(a - b))


@nb.njit(cache=True)
def patch_log_weights_mode(mode, patch, prior_lo, log_on, log_off, m_ref, f_ref, in_patch, ray_stamp, stamp,
                           offsets, cells, c_off, c_ray, c_kappa, ll, z, is_max, log_match, log_other, out):  # fmt: skip
    """``out[w]``: unnormalised log posterior of configuration ``w`` (prior included). Returns ``W``."""
    if mode == OFFLINE:
        return patch_log_weights(patch, prior_lo, m_ref, f_ref, in_patch, ray_stamp, stamp, offsets, cells, c_off,
                                 c_ray, c_kappa, ll, out)  # fmt: skip
    L, n_slots, slot_ray, slot_n, ent_kappa, ent_bit = collect_patch_rays(patch, c_off, c_ray, c_kappa, ray_stamp, stamp)
    W = 1 << L
    for w in range(W):
        out[w] = 0.0
    for i in range(patch.shape[0]):
        if patch[i] >= 0:
            in_patch[patch[i]] = True
    for s in range(n_slots):
        r = slot_ray[s]
        a = offsets[r]
        n = offsets[r + 1] - a
        if mode == ONLINE:
            # running log A (reflection by an outside cell before j) and log B (outside cells before
            # j all free) along the ray, recorded at the patch kappas and at the end
            logA = -np.inf
            logB = 0.0
            rec_A = np.empty(slot_n[s] + 1, np.float64)
            rec_B = np.empty(slot_n[s] + 1, np.float64)
            for j in range(n + 1):
                for e in range(slot_n[s]):
                    if ent_kappa[s, e] == j:
                        rec_A[e] = logA
                        rec_B[e] = logB
                if j == n:
                    rec_A[slot_n[s]] = logA
                    rec_B[slot_n[s]] = logB
                    break
                c = cells[a + j]
                if not in_patch[c]:
                    logA = _logaddexp(logA, logB + log_on[c] + ll[r, j])
                    logB += log_off[c]
            none_term = _logaddexp(rec_A[slot_n[s]], rec_B[slot_n[s]] + ll[r, n])
            for w in range(W):
                best = -1
                for e in range(slot_n[s]):
                    if (w >> ent_bit[s, e]) & 1 and (best < 0 or ent_kappa[s, e] < ent_kappa[s, best]):
                        best = e
                if best < 0:
                    out[w] += none_term
                else:
                    out[w] += _logaddexp(rec_A[best], rec_B[best] + ll[r, ent_kappa[s, best]])
        else:  # INVERSE
            zr = n if is_max[r] else z[r]
            constrained = 0
            for e in range(slot_n[s]):
                if ent_kappa[s, e] <= zr:
                    constrained += 1
            if constrained == 0:
                continue
            # configurations matching the reading: 2^(L - constrained) of W
            log_m = log_match - (L - constrained) * math.log(2.0)
            n_other = W - (1 << (L - constrained))
            log_o = log_other - math.log(n_other) if n_other > 0 else -np.inf
            for w in range(W):
                ok = True
                for e in range(slot_n[s]):
                    k = ent_kappa[s, e]
                    bit = (w >> ent_bit[s, e]) & 1
                    if (k < zr and bit == 1) or (k == zr and bit == 0 and not is_max[r]):
                        ok = False
                        break
                out[w] += log_m if ok else log_o
    for i in range(patch.shape[0]):
        if patch[i] >= 0:
            in_patch[patch[i]] = False
    add_patch_prior(patch, prior_lo, out, W)
    return W


@nb.njit(cache=True)
def patch_map_all(mode, patches, centre, prior_lo, log_on, log_off, m_ref, f_ref, offsets, cells, c_off, c_ray,
                  c_kappa, ll, z, is_max, log_match, log_other, keep_weights):  # fmt: skip
    """Weigh every patch. Returns (marginals ``P x L`` of each patch cell, normalised log weights
    ``P x W`` if ``keep_weights`` else an empty array). ``centre >= 0`` fills only that column."""
    P, L = patches.shape
    W = 1 << L
    K = m_ref.shape[0]
    in_patch = np.zeros(K, np.bool_)
    ray_stamp = np.full((offsets.shape[0] - 1, 2), -1, np.int64)
    logw = np.empty(W, np.float64)
    marg = np.zeros((P, L), np.float64)
    weights = np.empty((P if keep_weights else 0, W), np.float64)
    for p in range(P):
        patch = patches[p]
        Wp = patch_log_weights_mode(mode, patch, prior_lo, log_on, log_off, m_ref, f_ref, in_patch, ray_stamp, p,
                                    offsets, cells, c_off, c_ray, c_kappa, ll, z, is_max, log_match, log_other,
                                    logw)  # fmt: skip
        mx = -np.inf
        for w in range(Wp):
            if logw[w] > mx:
                mx = logw[w]
        tot = 0.0
        for w in range(Wp):
            tot += math.exp(logw[w] - mx)
        lz = mx + math.log(tot)
        if keep_weights:
            for w in range(W):
                weights[p, w] = logw[w] - lz if w < Wp else -np.inf
        bit = 0
        for j in range(L):
            c = patch[j]
            if c < 0:
                continue
            if centre < 0 or j == centre:
                acc = 0.0
                for w in range(Wp):
                    if (w >> bit) & 1:
                        acc += math.exp(logw[w] - lz)
                marg[p, j] = acc
            bit += 1
    return marg, weights
