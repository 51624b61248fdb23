r"""Exact transition matrices of patch Gibbs on table priors whose tiles are the patches, on enumerable
problems: the restricted heat bath + escape move of backed-off tables, and the thesis's border update.

:func:`~ogm_ppl.testing.kernels.sweep_matrix` knows patch updates that draw from the full conditional.
:class:`~ogm_ppl.inference.mcmc.PatchGibbs` on a backed-off table (a restricted candidate set, see
:func:`~ogm_ppl.inference._kernels.candidate_sweep._restricted_update`) and with ``update="thesis"`` (Section 5.2.3:
each tile drawn from ``p(a_k | border_k)`` times the likelihood, the neighbouring tiles' factors ignored)
do something else; :func:`tile_update_matrix` builds their one-update matrices from the pieces the
compiled kernel reads (the candidates and the tile's own weights of
:func:`~ogm_ppl.priors.compiled.patch_candidates`, the back-off table's ``back_cdf``, the full conditional
of :meth:`PatchGibbs.patch_log_weights` and the likelihood of :func:`patch_log_lik`), written out here
independently of the kernel's code. All matrices are ``2^L x 2^L`` over
:func:`~ogm_ppl.testing.kernels.enumerate_maps`.
"""

from __future__ import annotations

import numpy as np
import torch

from ogm_ppl.inference._kernels.patch_lik import patch_log_lik
from ogm_ppl.priors.compiled.registry import patch_candidates, restricted
from ogm_ppl.testing.kernels import _codes, enumerate_maps

__all__ = ["marginal_gap", "stationary", "tile_sweep_matrix", "tile_update_matrix"]


def _softmax(x: np.ndarray) -> np.ndarray:
    x = np.asarray(x, np.float64)
    if not np.isfinite(x).any():
        return np.zeros_like(x)
    e = np.exp(x - x.max())
    return e / e.sum()


def _candidates(kernel, anchor, patch, m):
    lp = kernel._compiled
    h, w = kernel._hw
    cap = kernel._patch_rule().capacity
    cands, clp = np.empty(cap, np.int64), np.empty(cap, np.float64)
    n, t = patch_candidates(
        lp, int(anchor[0]), int(anchor[1]), h, w, patch, int((patch >= 0).sum()), kernel._pinned, m, cands, clp
    )
    return cands[:n].copy(), clp[:n].copy(), int(t)


def _escape_q(kernel, t, patch, m) -> np.ndarray:
    """``q[c']``: the chance the escape move proposes live code ``c'`` (incompatible draws: the rest)."""
    lp = kernel._compiled
    cdf = lp.back_cdf
    back = np.diff(np.concatenate([[0.0], cdf]))
    Li = lp.n_inner
    ti, tj = divmod(t, lp.t_cols)
    ar, ac = lp.t_r0 + ti * lp.t_h, lp.t_c0 + tj * lp.t_w
    cur_inner = 0
    for i in range(Li):  # the current inner code, off-grid cells at their fill
        r, c = ar + lp.w_dr[i], ac + lp.w_dc[i]
        on = 0 <= r < lp.rows and 0 <= c < lp.cols
        v = m[r * lp.cols + c] if on else (lp.t_fill[t] >> i) & 1
        cur_inner |= int(v) << i
    live = patch >= 0
    q = np.zeros(1 << int(live.sum()))
    for code in range(1 << Li):
        bits = (code >> np.arange(Li)) & 1
        if (bits[~live] != ((cur_inner >> np.arange(Li)) & 1)[~live]).any():
            continue
        q[int((bits[live] << np.arange(int(live.sum()))).sum())] += back[code]
    return q


def tile_update_matrix(kernel, index: int, rows=None) -> torch.Tensor:
    """The exact one-update matrix of patch ``index`` of ``kernel.patches()`` (a :class:`PatchGibbs` on a
    table prior whose tiles are its patches, ``p_rand_patch = 0``; heat-bath or ``"thesis"`` update)."""
    model = kernel.model
    S = enumerate_maps(model)
    rows = range(len(S)) if rows is None else rows
    T = torch.zeros(len(S), len(S), dtype=torch.float64)
    patch = np.ascontiguousarray(kernel.patches()[index], np.int64)
    anchor = kernel._anchors[index]
    live = patch[patch >= 0]
    L = len(live)
    W = 1 << L
    for i in rows:
        s = S[i]
        kernel.set_state(s)
        m = kernel.state
        cur = int(sum(int(s[c]) << j for j, c in enumerate(live)))
        cands, clp, t = _candidates(kernel, anchor, patch, m)
        row = np.zeros(W)
        if kernel.update == "thesis":
            lik = np.empty(W)
            patch_log_lik(kernel._ps, patch, lik)
            if len(cands):
                row[cands] = _softmax(clp + lik[cands])
            else:
                row[cur] = 1.0
        else:
            logw = np.asarray(kernel.patch_log_weights(patch), np.float64)  # the full conditional
            if restricted(kernel._compiled, t):
                A = np.zeros((W, W))
                A[np.arange(W), np.arange(W)] = 1.0
                # step A from cur only needs row `cur`; step B needs rows from every state A can reach
                if cur in set(cands.tolist()) and len(cands) > 1:
                    A[cur] = 0.0
                    A[cur, cands] = _softmax(logw[cands])
                q = _escape_q(kernel, t, patch, m)
                pe = kernel.p_escape
                B = np.zeros((W, W))
                for c in np.flatnonzero(A[cur]):
                    for c2 in np.flatnonzero(q):
                        if c2 != c and q[c] > 0:
                            a = min(1.0, float(np.exp(logw[c2] - logw[c] + np.log(q[c]) - np.log(q[c2]))))
                            B[c, c2] = pe * q[c2] * a
                    B[c, c] = 1.0 - B[c].sum()
                row = A[cur] @ B
            else:
                row = _softmax(logw[cands]) @ np.eye(W)[cands] if len(cands) else np.eye(W)[cur]
        for w in np.flatnonzero(row):
            tt = s.clone()
            tt[torch.from_numpy(live)] = torch.tensor([(w >> j) & 1 for j in range(L)], dtype=torch.float64)
            T[i, int(_codes(model, tt))] += float(row[w])
    return T


def tile_sweep_matrix(kernel) -> torch.Tensor:
    """One systematic sweep: the product of :func:`tile_update_matrix` over the kernel's patches."""
    P = torch.eye(2 ** len(kernel.model.latent), dtype=torch.float64)
    for k in range(len(kernel.patches())):
        P = P @ tile_update_matrix(kernel, k)
    return P


def stationary(P: torch.Tensor) -> torch.Tensor:
    """The stationary distribution of an irreducible stochastic matrix (solve ``pi (P - I) = 0``,
    ``sum pi = 1`` by least squares)."""
    n = len(P)
    A = torch.cat([(P - torch.eye(n, dtype=P.dtype)).T, torch.ones(1, n, dtype=P.dtype)])
    b = torch.zeros(n + 1, dtype=P.dtype)
    b[-1] = 1.0
    pi = torch.linalg.lstsq(A, b[:, None]).solution[:, 0]
    return pi.clamp_min(0) / pi.clamp_min(0).sum()


def marginal_gap(model, pi: torch.Tensor, exact: torch.Tensor) -> dict:
    """Max abs error of the cell marginals and the total variation between two distributions over
    :func:`enumerate_maps`."""
    S = enumerate_maps(model)[:, model.latent]
    mp, me = pi @ S, exact @ S
    return {
        "max_abs_marginal_error": float((mp - me).abs().max()),
        "total_variation": float(0.5 * (pi - exact).abs().sum()),
    }
