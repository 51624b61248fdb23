"""Patch updates under priors whose weights add over cells (independent cells): every update weighs all
``W = 2^L`` configurations, the likelihood in ``O(W)`` per ray plus each configuration's cells' prior
log-odds (also in ``O(W)``: the prior of ``w`` is that of ``w`` without its lowest bit plus that bit's
cell's log-odds).
"""

from __future__ import annotations

import numpy as np

from ogm_ppl._numba_cache import njit_shipped
from ogm_ppl.inference._kernels.choice import accept_random, choose
from ogm_ppl.inference._kernels.patch_lik import GROUP_MIN_CANDS, lik_all, lik_grouped, patch_log_lik
from ogm_ppl.inference._kernels.patch_rays import collect_rays, max_slots, ray_scratch
from ogm_ppl.inference._kernels.patch_state import build_patch, patch_config, set_patch
from ogm_ppl.priors.compiled import cell_log_odds


@njit_shipped
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


@njit_shipped
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


@njit_shipped
def additive_patch_log_weights(ps, patch, prior, logw):
    """Unnormalised log conditional of every configuration of ``patch`` under an additive prior
    (likelihood first, then the cells' log-odds). Returns ``W``."""
    W = patch_log_lik(ps, patch, logw)
    add_patch_prior(patch, prior, ps.m, logw, W)
    return W


@njit_shipped
def _additive_sweep(ps, geo, anchors, prior, u, rule, stamp0, bit_of):
    """Patch updates that weigh all ``W = 2^L`` configurations: the likelihood through the rays of the
    patch (:func:`collect_rays`; :func:`lik_grouped` over all ``W`` codes, else :func:`lik_all`: ``O(W)``
    per ray) plus the cells' prior log-odds.
    ``stamp0``: the first of ``len(anchors)`` fresh stamps; ``bit_of`` is not read (see :func:`patch_pass`)."""
    L = geo.dr.shape[0]
    logw = np.empty(1 << L, np.float64)
    codes = np.arange(1 << L)  # every configuration, in order: the candidates of lik_grouped
    patch = np.empty(L, np.int64)
    sc = ray_scratch(L, max_slots(L, ps), np.bool_(True), np.int64(0))
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
