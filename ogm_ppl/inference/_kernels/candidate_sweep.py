"""Patch updates that weigh the candidate configurations the prior's kind allows given the rest of the map
(a tile's sparse support, else all ``2^L``), the rays' terms grouped by the patch cells they cross, with the
exact two-step update of restricted candidate sets (:func:`_restricted_update`). The loop is compiled
once per prior bundle type (:mod:`ogm_ppl.priors.compiled`), without numba's runtime where the kind allows.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba.extending import overload

from ogm_ppl._numba_cache import njit_shipped
from ogm_ppl.inference._kernels.choice import accept_random, categorical, categorical_table, choose, pick_from_table
from ogm_ppl.inference._kernels.patch_lik import _add_lik, lik_list
from ogm_ppl.inference._kernels.patch_rays import RayScratch, collect_rays, max_slots, patch_slots, ray_scratch
from ogm_ppl.inference._kernels.patch_state import _next_stamp, build_patch, patch_config, set_patch
from ogm_ppl.priors.compiled import candidate_weights, patch_candidates, scratch_capacity
from ogm_ppl.priors.compiled.registry import (
    escape_proposal,
    patch_allocates,
    restricted,
    shared_weights,
    shared_weights_key,
)
from ogm_ppl.priors.compiled.scratch import TileScratch, tile_scratch, tile_scratch_on


class UpdateScratch(NamedTuple):
    """The buffers one patch update fills (one numba argument; :func:`_candidate_sweep` allocates them once)."""

    cands: np.ndarray  # capacity int64: the candidate configurations
    cand_lp: np.ndarray  # capacity float64: the tile's own log factor of each candidate
    logw: np.ndarray  # capacity float64: each candidate's unnormalised log conditional
    pair: np.ndarray  # 2 int64: the current and the proposed configuration of a Metropolis-Hastings move
    pw: np.ndarray  # 2 float64: their log weights
    sc: RayScratch  # the ray collection's scratch
    ts: TileScratch  # the prior's scratch


@njit_shipped
def candidate_log_weights(ps, patch, prior, cands, n, logw):
    """``logw[j]``: unnormalised log conditional of ``cands[j]`` (prior first; the likelihood only for
    candidates the prior allows)."""
    sc = ray_scratch(patch.shape[0], patch_slots(patch, ps.c_off, ps.offsets.shape[0] - 1), np.bool_(False), n)
    ts = tile_scratch(ps.m.shape[0], np.int64(scratch_capacity(prior, patch.shape[0])))
    candidate_weights(prior, patch, ps.m, cands, n, -1, logw, logw, ts)
    ns = collect_rays(ps, patch, _next_stamp(ps, 1), sc)
    lik_list(sc, ns, ps.ll, cands, n, logw)


@njit_shipped
def _restricted_update(ps, patch, prior, u, i, rule, stamp, n, t, work):
    r"""One exact update of a patch whose candidates ``work.cands[:n]`` (a set ``S`` fixed by the cells outside
    the patch, e.g. the configurations a backed-off table counted after the tile's border) are only part
    of the configurations with mass (:func:`~ogm_ppl.priors.compiled.restricted`); ``t`` and
    ``work.cand_lp[:n]`` as :func:`~ogm_ppl.priors.compiled.patch_candidates` gives them, ``u[:, i]`` the
    update's uniforms, ``work`` its :class:`UpdateScratch`. Two steps, each
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
    cands, cand_lp, logw, pair, pw, sc, ts = work
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
            lik_list(sc, ns, ll, pair, np.int64(2), pw)
            d = pw[1] - pw[0] + log_q
            if pw[0] == -np.inf or d >= 0.0 or (d > -np.inf and u[4, i] < math.exp(d)):
                set_patch(ps, patch, prop)
                new = prop
    return new != cur


@njit_shipped
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
    ts = tile_scratch_on(bit_of, np.int64(scratch_capacity(prior, L)))
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


@njit_shipped(inline="always")
def _candidate_loop_body(ps, geo, anchors, prior, u, rule, stamp0, scratch):
    """The loop of :func:`_candidate_sweep` over its scratch (inlined into :func:`_candidate_loop_rt` and
    :func:`_candidate_loop_lean`)."""
    cands, cand_lp, logw, patch, pair, pw, sc, ts, n_keys, key_n, key_total, key_last, key_acc, key_cands, key_lw = (
        scratch
    )
    work = UpdateScratch(cands, cand_lp, logw, pair, pw, sc, ts)
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
                lik_list(sc, ns, ll, pair, np.int64(2), pw)
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
                    if _restricted_update(ps, patch, prior, u, i, rule, stamp, n, t, work):
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


@njit_shipped
def _candidate_loop_rt(ps, geo, anchors, prior, u, rule, stamp0, scratch):
    """:func:`_candidate_loop_body` with numba's runtime (for patch conditionals that allocate)."""
    return _candidate_loop_body(ps, geo, anchors, prior, u, rule, stamp0, scratch)


@njit_shipped(_nrt=False)
def _candidate_loop_lean(ps, geo, anchors, prior, u, rule, stamp0, scratch):
    """:func:`_candidate_loop_body` without numba's runtime, which counts the references of every bundle
    array at each inlined call (the prior, the patch state, the scratch), a share of each patch update (as
    in :func:`~ogm_ppl.inference._kernels.cell_sweep.sweep`); only for kinds registered with
    ``patch_allocates=False``."""
    return _candidate_loop_body(ps, geo, anchors, prior, u, rule, stamp0, scratch)
