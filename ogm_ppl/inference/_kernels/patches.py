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
from typing import NamedTuple

import numba as nb
import numpy as np

from ogm_ppl._numba_cache import njit_shipped
from ogm_ppl.inference._kernels.additive_sweep import add_patch_prior, additive_patch_log_weights
from ogm_ppl.inference._kernels.patch_rays import collect_patch_rays

OFFLINE, ONLINE, INVERSE = 0, 1, 2


class PatchSensor(NamedTuple):
    """What the online and inverse weights read beside the rays: the cells' log prior occupancy and
    vacancy, each ray's reading (kappa) and max-range flag, and the inverse model's log masses."""

    log_on: np.ndarray  # K float64: log lambda_k
    log_off: np.ndarray  # K float64: log(1 - lambda_k)
    z: np.ndarray  # R int64
    is_max: np.ndarray  # R bool
    log_match: float
    log_other: float


@nb.njit(cache=True, inline="always")
def _logaddexp(a, b):
    if a == -np.inf:
        return b
    if b == -np.inf:
        return a
    if a > b:
        return a + math.log1p(math.exp(b - a))
    return b + math.log1p(math.exp(a - b))


@njit_shipped
def patch_log_weights_mode(mode, ps, patch, prior, sensor, out):
    """``out[w]``: unnormalised log posterior of configuration ``w`` (prior included), with the reference
    map and its first hits in the :class:`~ogm_ppl.inference._kernels.patch_state.PatchState` ``ps``. Returns ``W``."""
    if mode == OFFLINE:
        return additive_patch_log_weights(ps, patch, prior, out)
    in_patch, offsets, cells, ll = ps.in_patch, ps.offsets, ps.cells, ps.ll
    log_on, log_off, z, is_max = sensor.log_on, sensor.log_off, sensor.z, sensor.is_max
    log_match, log_other = sensor.log_match, sensor.log_other
    stamp = ps.stamp[0]
    ps.stamp[0] = stamp + 1
    L, n_slots, slot_ray, slot_n, ent_kappa, ent_bit = collect_patch_rays(ps, patch, stamp)
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
    add_patch_prior(patch, prior, ps.m, out, W)
    return W


@njit_shipped
def patch_map_all(mode, patches, centre, ps, prior, sensor, keep_weights):
    """Weigh every patch. Returns (marginals ``P x L`` of each patch cell, normalised log weights
    ``P x W`` if ``keep_weights`` else an empty array). ``centre >= 0`` fills only that column."""
    P, L = patches.shape
    W = 1 << L
    logw = np.empty(W, np.float64)
    marg = np.zeros((P, L), np.float64)
    weights = np.empty((P if keep_weights else 0, W), np.float64)
    for p in range(P):
        patch = patches[p]
        Wp = patch_log_weights_mode(mode, ps, patch, prior, sensor, logw)
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
