r"""The patch conditionals, whole-map energies and prior sweeps of the net-field kind
(:class:`~ogm_ppl.priors.compiled.net_field.NetField`; the energy and its edge convention: that module).

**Patch weights** (:func:`net_patch_weights`): every window holding a live cell of the patch is read once, its
pre-activation with the live cells cleared (``base_q``, ``U`` floats) and its (live bit, weight column) pairs.
A configuration ``g`` of the live cells scores ``a |g| + sum_q sum_u v_u sigma(base_q,u + sum_{pairs (x, p) of q,
bit x of g set} W_u[p])``. All ``2^L`` configurations (a patch Gibbs update) are visited in Gray-code order: step
``i`` flips live bit ``ctz(i)``, which moves only the ``w^2`` windows holding that cell, by one weight column each,
and the running sum by their activation differences; every :data:`GRAY_RESYNC` steps the windows are summed
afresh from ``base`` (a bound on the rounding). Other candidate lists are scored one by one.

**Prior sweeps** (:func:`net_prior_sweeps`, the negative chains of learning and
:meth:`~ogm_ppl.priors.NetFieldPrior.sample`): the generic prior sweeps through the bundle's memo of conditionals.
"""

from __future__ import annotations

import numpy as np

from ogm_ppl._numba_cache import njit_shipped
from ogm_ppl.priors.compiled.field_patches import full_range, live_cells
from ogm_ppl.priors.compiled.net_ops import act_sum, window_pre
from ogm_ppl.priors.compiled.sampling import prior_gibbs_sweeps

__all__ = ["GRAY_RESYNC", "net_log_prob_batch", "net_patch_weights", "net_prior_sweeps"]

#: sum the Gray-code walk's windows afresh every this many steps
GRAY_RESYNC = 64


@njit_shipped
def _patch_windows(nf, m, cr, cc, nl, bit_of, base, pr_off, pr_pb, pr_p):
    """The windows holding one of the ``nl`` live cells ``(cr, cc)`` (``bit_of[k]``: the live bit of grid cell
    ``k``, else -1), each once (owned by its first live cell): ``base[q U : (q + 1) U]`` its pre-activation with
    the live cells cleared, pairs ``pr_off[q] .. pr_off[q + 1]`` its (live bit ``pr_pb``, weight column
    ``pr_p``). Returns the number of windows."""
    R, C, w, U = nf.rows, nf.cols, nf.w, nf.units
    wt = nf.wt
    nw = 0
    npair = 0
    pr_off[0] = 0
    for x in range(nl):
        r = cr[x]
        c = cc[x]
        for a in range(w):
            for b in range(w):
                r0 = r - a
                c0 = c - b
                owned = True
                for i in range(w):
                    for j in range(w):
                        rr = r0 + i
                        c1 = c0 + j
                        if 0 <= rr < R and 0 <= c1 < C:
                            q = bit_of[rr * C + c1]
                            if q >= 0 and q < x:
                                owned = False
                if not owned:
                    continue
                window_pre(nf, m, r0, c0, -1, base, nw * U)
                for i in range(w):
                    for j in range(w):
                        rr = r0 + i
                        c1 = c0 + j
                        if 0 <= rr < R and 0 <= c1 < C:
                            kk = rr * C + c1
                            q = bit_of[kk]
                            if q >= 0:
                                p = (i * w + j) * U
                                pr_pb[npair] = q
                                pr_p[npair] = p
                                npair += 1
                                if m[kk]:  # read as free in base
                                    for u in range(U):
                                        base[nw * U + u] -= wt[p + u]
                nw += 1
                pr_off[nw] = npair
    return nw


@njit_shipped(inline="always")
def _config_pre(nf, base, q, pr_off, pr_pb, pr_p, g, cur):
    """``cur[q U : (q + 1) U] = base_q + sum of the columns of q's live bits set in g``."""
    U = nf.units
    o = q * U
    for u in range(U):
        cur[o + u] = base[o + u]
    for e in range(pr_off[q], pr_off[q + 1]):
        if (g >> pr_pb[e]) & 1:
            p = pr_p[e]
            for u in range(U):
                cur[o + u] += nf.wt[p + u]


@njit_shipped
def _gray_walk(nf, nw, nl, base, pr_off, pr_pb, pr_p, out):
    """``out[g]`` for every configuration ``g < 2^nl`` by the Gray-code walk (module docstring)."""
    U = nf.units
    # per live bit: the (window, column) pairs it enters
    cnt = np.zeros(nl + 1, np.int64)
    for e in range(pr_off[nw]):
        cnt[pr_pb[e] + 1] += 1
    for x in range(nl):
        cnt[x + 1] += cnt[x]
    fill = cnt[:nl].copy()
    xq = np.empty(max(pr_off[nw], 1), np.int64)
    xp = np.empty(max(pr_off[nw], 1), np.int64)
    for q in range(nw):
        for e in range(pr_off[q], pr_off[q + 1]):
            x = pr_pb[e]
            xq[fill[x]] = q
            xp[fill[x]] = pr_p[e]
            fill[x] += 1
    cur = base[: nw * U].copy()
    F = np.empty(nw)
    s = 0.0
    for q in range(nw):
        F[q] = act_sum(cur, q * U, nf.out, U, nf.act)
        s += F[q]
    out[0] = s
    g = np.int64(0)
    for i in range(1, np.int64(1) << nl):
        x = 0
        while not (i >> x) & 1:
            x += 1
        g ^= np.int64(1) << x
        sign = 1.0 if (g >> x) & 1 else -1.0
        if i % GRAY_RESYNC == 0:
            s = 0.0
            for q in range(nw):
                _config_pre(nf, base, q, pr_off, pr_pb, pr_p, g, cur)
                F[q] = act_sum(cur, q * U, nf.out, U, nf.act)
                s += F[q]
        else:
            for e in range(cnt[x], cnt[x + 1]):
                q = xq[e]
                p = xp[e]
                o = q * U
                for u in range(U):
                    cur[o + u] += sign * nf.wt[p + u]
                Fn = act_sum(cur, o, nf.out, U, nf.act)
                s += Fn - F[q]
                F[q] = Fn
        out[g] = s


@njit_shipped
def net_patch_weights(nf, patch, m, cands, n, out, ts):
    """``out[j] = log p~(patch = cands[j], rest)`` up to a constant in ``j`` (bit ``b`` of a candidate: the
    ``b``-th live cell of ``patch``; -1 entries are pinned cells): the windows holding a live cell read once, then
    all ``2^L`` candidates in order by the Gray-code walk, or each candidate scored alone."""
    C, w, U = nf.cols, nf.w, nf.units
    L = patch.shape[0]
    bit_of = ts.bit_of  # K int64, all -1 between updates
    nl, cr, cc = live_cells(patch, bit_of, C)
    cap = max(nl, 1) * w * w
    base = np.empty(cap * U)
    pr_off = np.empty(cap + 1, np.int64)
    pr_pb = np.empty(cap, np.int64)
    pr_p = np.empty(cap, np.int64)
    nw = _patch_windows(nf, m, cr, cc, nl, bit_of, base, pr_off, pr_pb, pr_p)
    for i in range(L):
        if patch[i] >= 0:
            bit_of[patch[i]] = -1
    if full_range(cands, n, nl):
        _gray_walk(nf, nw, nl, base, pr_off, pr_pb, pr_p, out)
    else:
        cur = np.empty(max(nw, 1) * U)
        for jx in range(n):
            g = cands[jx]
            s = 0.0
            for q in range(nw):
                _config_pre(nf, base, q, pr_off, pr_pb, pr_p, g, cur)
                s += act_sum(cur, q * U, nf.out, U, nf.act)
            out[jx] = s
    for jx in range(n):
        g = cands[jx]
        ones = 0
        for x in range(nl):
            ones += (g >> x) & 1
        out[jx] += nf.unary * ones


# ------------------------------------------------------------------ whole maps
@njit_shipped
def _fill(nf, m, pre, F):
    """Every window's pre-activation (``pre``, anchors row-major from ``(-(w - 1), -(w - 1))``) and activation sum
    ``F``; returns ``sum F``."""
    w, U = nf.w, nf.units
    AC = nf.cols + w - 1
    tot = 0.0
    for ar in range(nf.rows + w - 1):
        for ac in range(AC):
            q = ar * AC + ac
            window_pre(nf, m, ar - (w - 1), ac - (w - 1), -1, pre, q * U)
            F[q] = act_sum(pre, q * U, nf.out, U, nf.act)
            tot += F[q]
    return tot


@njit_shipped
def net_log_prob_batch(nf, maps, out):
    """``log p~(m)`` for every row of ``maps`` (``B x K`` uint8)."""
    w, U = nf.w, nf.units
    nA = (nf.rows + w - 1) * (nf.cols + w - 1)
    pre = np.empty(nA * U)
    F = np.empty(nA)
    for bi in range(maps.shape[0]):
        m = maps[bi]
        s = _fill(nf, m, pre, F)
        ones = 0
        for k in range(m.shape[0]):
            ones += m[k]
        out[bi] = s + nf.unary * ones


def net_prior_sweeps(nf, maps, num_sweeps: int, seed: int) -> None:
    """Single-cell Gibbs sweeps on the prior alone for each row of ``maps`` (``B x K`` uint8), in place: the generic
    :func:`~ogm_ppl.priors.compiled.prior_gibbs_sweeps` through the bundle's memo of conditionals
    (:mod:`~ogm_ppl.priors.compiled.net_memo`; the chains share it, its values being functions of the map content
    alone)."""
    prior_gibbs_sweeps(nf, maps, int(num_sweeps), int(seed))
