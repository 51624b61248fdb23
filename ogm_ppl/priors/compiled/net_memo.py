r"""The memo of a net field's cell conditionals (:class:`~ogm_ppl.priors.compiled.net_field.NetField`), the prior
term of the single-cell Gibbs update (Section 4.1, Eq. 4.2): the single-cell kernels call
``cell_log_odds(prior, k, m)`` with the chain's map alone, so the bundle keeps what it computed keyed by the map
content it depends on, never by which chain asked.

**Cell memo.** A cell's conditional ``l_k`` depends on its position and the ``S x S`` cells around it
(``S = 2w - 1``: every cell of the ``w^2`` windows holding it). :func:`nbhd_key` packs those cells (the cell itself
too: its value changes how the window terms below round, so keying on it keeps every kept value a function of its
key) into ``key_words(w)`` int64 words (bit ``i S + j`` for row ``i``, column ``j``; 0 past the grid's
edge; a marker bit ``S^2`` that no zeroed, unset key has); the bundle keeps one key and one ``l_k`` per cell and
returns the kept value while the key is unchanged. A visit then costs ``S`` 8-byte loads and a compare (for
``w <= 6`` the key is two words in registers, :func:`nbhd_key2`) instead of ``w^2`` windows of ``U`` units. A
flip of cell ``j`` changes the keys of the ``S^2`` cells around it, which miss once.

**Window memo** (``w <= 7``). A miss sums the cell's ``w^2`` windows' terms ``Delta_q(p) = sum_u v_u
(sigma(base_q,u + W_u[p]) - sigma(base_q,u))``, ``base_q`` the window's pre-activation with its cell ``p``
cleared. Each window anchor keeps its content (:func:`window_key`, ``w^2`` bits and a marker) and the ``w^2``
terms of its cells (:func:`window_deltas`: one pre-activation ``pre`` and ``U (w^2 + 1)`` activations, vectorised
over the window's cells,
``Delta_q(p) = S(pre + W[p]) - S(pre)`` for a free cell ``p``, ``S(pre) - S(pre - W[p])`` for an occupied one,
``S(x) = sum_u v_u sigma(x_u)``); a missed cell reads
``w^2`` kept terms, and a flip recomputes the ``w^2`` windows holding the flipped cell once. Wider windows
(``w >= 8``, keys past one word) compute a missed cell afresh
(:func:`~ogm_ppl.priors.compiled.net_ops.fresh_log_odds`).

Every kept value is a function of the content in its key alone, computed in a fixed order, so a conditional is
the same number whichever map, chain or history led to it. The memo arrays belong to one bundle: a tempered,
biased or windowed bundle gets empty ones (:func:`memo_arrays`). Updates of one map by several threads (the
chromatic kernels) touch disjoint cells whose neighbourhoods do not change during a colour; one bundle must not
serve concurrent chains of different maps.
"""

from __future__ import annotations

import numpy as np

from ogm_ppl._numba_cache import njit_shipped
from ogm_ppl.priors.compiled.field import _load8
from ogm_ppl.priors.compiled.net_ops import (
    MAX_NET_WINDOW,
    MAX_UNITS,
    act_sum,
    fresh_log_odds,
    softplus,
    stack_f64,
    stack_i64,
    window_pre,
)

__all__ = [
    "KEY_WORDS",
    "MAX_KEY2_WINDOW",
    "MAX_WINDOW_MEMO",
    "key_words",
    "memo_arrays",
    "memo_log_odds",
    "nbhd_key",
    "nbhd_key2",
    "window_deltas",
    "window_key",
    "windowed_log_odds",
]

#: gathers the low bits of 0/1 bytes 0..7 of a word to bits 56..63 (the partial products never collide)
_GATHER8 = np.int64(0x0102040810204080)
#: the largest window side whose cell keys fit two words (:func:`nbhd_key2`)
MAX_KEY2_WINDOW = 6
#: the largest window side with a window memo (a window's ``w^2`` cells and a marker in one int64)
MAX_WINDOW_MEMO = 7
#: the most cells of a window with a window memo
MAX_WINDOW_CELLS = MAX_WINDOW_MEMO**2


def key_words(w: int) -> int:
    """int64 words of a cell's neighbourhood key (:func:`nbhd_key`): ``(2w - 1)^2`` cell bits and one marker bit."""
    return (2 * w - 1) ** 2 // 64 + 1


#: the most words a key takes (``w = 9``)
KEY_WORDS = key_words(MAX_NET_WINDOW)


def memo_arrays(rows: int, cols: int, w: int) -> dict:
    """Empty memo arrays of a ``rows x cols`` bundle of window side ``w`` (every key zero: nothing kept): ``kw``,
    ``memo_key`` (``rows cols kw`` int64), ``memo_lo`` (``rows cols``), ``win_key`` (one a window anchor, ``(rows +
    w - 1) (cols + w - 1)``) and ``win_delta`` (``w^2`` a window anchor; both empty for ``w > 7``)."""
    rows, cols, w = int(rows), int(cols), int(w)
    kw = key_words(w)
    n_win = (rows + w - 1) * (cols + w - 1) if w <= MAX_WINDOW_MEMO else 0
    return {
        "kw": kw,
        "memo_key": np.zeros(rows * cols * kw, np.int64),
        "memo_lo": np.zeros(rows * cols),
        "win_key": np.zeros(n_win, np.int64),
        "win_delta": np.zeros(n_win * w * w),
    }


@njit_shipped(inline="always")
def _gather(m, at):
    """Cells ``m[at : at + 8]`` (each 0 or 1) as 8 bits, cell ``at + b`` at bit ``b`` (one 8-byte load)."""
    return ((_load8(m, at) * _GATHER8) >> 56) & 0xFF


@njit_shipped(inline="always")
def nbhd_key(nf, k, m, key):
    """``key[: nf.kw]``: the cells of the ``S x S`` neighbourhood of cell ``k`` (``S = 2w - 1``, every cell of the
    ``w^2`` windows holding it, ``k`` too), bit ``i S + j`` for row ``i``, column ``j`` (0 past the grid's edge),
    and a marker bit ``S^2``, which no zeroed key has. Two keys of a cell are equal only if its neighbourhoods are.
    Away from the edges each neighbourhood row is read by one to three 8-byte loads."""
    C, R, w = nf.cols, nf.rows, nf.w
    S = 2 * w - 1
    mask = (np.int64(1) << S) - 1
    nload = (S + 7) >> 3
    for i in range(nf.kw):
        key[i] = 0
    r = k // C
    c = k - r * C
    r0 = r - (w - 1)
    c0 = c - (w - 1)
    fast = r0 >= 0 and c0 >= 0 and r0 + S <= R and c0 + S <= C and (r0 + S - 1) * C + c0 + 8 * nload <= R * C
    acc = np.int64(0)
    filled = 0
    wd = 0
    for i in range(S):
        rr = r0 + i
        at = rr * C + c0
        bits = np.int64(0)
        if fast:
            bits = _gather(m, at)
            if nload > 1:
                bits |= _gather(m, at + 8) << 8
                if nload > 2:
                    bits |= _gather(m, at + 16) << 16
            bits &= mask
        elif 0 <= rr < R:
            for j in range(S):
                cc = c0 + j
                if 0 <= cc < C and m[at + j]:
                    bits |= np.int64(1) << j
        acc |= bits << filled
        if filled + S >= 64:
            key[wd] = acc
            wd += 1
            acc = bits >> (64 - filled)
            filled += S - 64
        else:
            filled += S
    key[wd] = acc
    key[(S * S) >> 6] |= np.int64(1) << ((S * S) & 63)


@njit_shipped(inline="always")
def nbhd_key2(nf, k, m):
    """:func:`nbhd_key` of a window side ``w <= 6`` (``S^2 + 1 <= 128`` bits) as two int64 words ``(lo, hi)`` in
    registers, each row of an interior cell's neighbourhood by two 8-byte loads."""
    C, R, w = nf.cols, nf.rows, nf.w
    S = 2 * w - 1
    mask = (np.int64(1) << S) - 1
    r = k // C
    c = k - r * C
    r0 = r - (w - 1)
    c0 = c - (w - 1)
    fast = r0 >= 0 and c0 >= 0 and r0 + S <= R and c0 + S <= C and (r0 + S - 1) * C + c0 + 16 <= R * C
    lo = np.int64(0)
    hi = np.int64(0)
    pos = 0
    for i in range(S):
        rr = r0 + i
        at = rr * C + c0
        bits = np.int64(0)
        if fast:
            bits = (_gather(m, at) | (_gather(m, at + 8) << 8)) & mask
        elif 0 <= rr < R:
            for j in range(S):
                cc = c0 + j
                if 0 <= cc < C and m[at + j]:
                    bits |= np.int64(1) << j
        if pos < 64:
            lo |= bits << pos
            if pos + S > 64:
                hi |= bits >> (64 - pos)
        else:
            hi |= bits << (pos - 64)
        pos += S
    if S * S < 64:
        lo |= np.int64(1) << (S * S)
    else:
        hi |= np.int64(1) << (S * S - 64)
    return lo, hi


@njit_shipped(inline="always")
def window_key(m, R, C, w, r0, c0):
    """The cells of the window anchored at ``(r0, c0)`` (``w <= 7``) of the ``R x C`` map ``m`` as bits ``i w + j``
    (0 past the grid's edge) and a marker bit ``w^2``: one 8-byte load a row inside the grid."""
    mask = (np.int64(1) << w) - 1
    key = np.int64(1) << (w * w)
    if r0 >= 0 and c0 >= 0 and r0 + w <= R and c0 + w <= C and (r0 + w - 1) * C + c0 + 8 <= R * C:
        for i in range(w):
            key |= (_gather(m, (r0 + i) * C + c0) & mask) << (i * w)
        return key
    for i in range(w):
        rr = r0 + i
        if 0 <= rr < R:
            for j in range(w):
                cc = c0 + j
                if 0 <= cc < C and m[rr * C + cc]:
                    key |= np.int64(1) << (i * w + j)
    return key


@njit_shipped(_nrt=False)
def window_deltas(nf, m, r0, c0, q):
    """``win_delta[q w^2 + p]`` for every grid cell ``p`` of the window anchored at ``(r0, c0)`` (anchor index
    ``q``): ``Delta_q(p)``, the window's change when its cell ``p`` turns occupied, read from ``m`` (module
    docstring). The inner loop runs over the window's cells (``wt_t``: the weights unit-major), so it
    vectorises. Allocates nothing (stack scratch)."""
    pre = stack_f64(MAX_UNITS)
    moved = stack_f64(MAX_WINDOW_CELLS)
    sgn = stack_f64(MAX_WINDOW_CELLS)
    C, R, w, U = nf.cols, nf.rows, nf.w, nf.units
    w2 = w * w
    window_pre(nf, m, r0, c0, -1, pre, 0)
    here = act_sum(pre, 0, nf.out, U, nf.act)
    for p in range(w2):
        i = p // w
        rr = r0 + i
        cc = c0 + p - i * w
        moved[p] = 0.0
        sgn[p] = 0.0
        if 0 <= rr < R and 0 <= cc < C:
            sgn[p] = -1.0 if m[rr * C + cc] else 1.0
    wt_t, out = nf.wt_t, nf.out
    if nf.act == 0:
        for u in range(U):
            x = pre[u]
            v = out[u]
            o = u * w2
            for p in range(w2):
                moved[p] += v * max(x + sgn[p] * wt_t[o + p], 0.0)
    else:
        for u in range(U):
            x = pre[u]
            v = out[u]
            o = u * w2
            for p in range(w2):
                moved[p] += v * softplus(x + sgn[p] * wt_t[o + p])
    o = q * w2
    for p in range(w2):
        if sgn[p] > 0.0:
            nf.win_delta[o + p] = moved[p] - here
        elif sgn[p] < 0.0:
            nf.win_delta[o + p] = here - moved[p]


@njit_shipped(_nrt=False)
def windowed_log_odds(nf, k, m):
    """``l_k`` from the window memo (``w <= 7``): ``a + sum`` of the kept terms of the cell's ``w^2`` windows,
    each window's terms recomputed where its content changed. (Without numba's runtime, as the sweeps: with it,
    every inlined use of the bundle would count the references of its arrays.)"""
    R, C, w = nf.rows, nf.cols, nf.w
    win_key, win_delta = nf.win_key, nf.win_delta
    AC = C + w - 1
    w2 = w * w
    r = k // C
    c = k - r * C
    lo = nf.unary
    for a in range(w):
        for b in range(w):
            r0 = r - a
            c0 = c - b
            q = (r0 + w - 1) * AC + (c0 + w - 1)
            key = window_key(m, R, C, w, r0, c0)
            if win_key[q] != key:
                window_deltas(nf, m, r0, c0, q)
                win_key[q] = key
            lo += win_delta[q * w2 + a * w + b]
    return lo


@njit_shipped(inline="always")
def _miss(nf, k, m):
    """A missed cell's log-odds: from the window memo, or afresh for ``w > 7``."""
    if nf.w <= MAX_WINDOW_MEMO:
        return windowed_log_odds(nf, k, m)
    return fresh_log_odds(nf, k, m)


@njit_shipped(_nrt=False)
def _keep2(nf, k, m, lo_key, hi_key):
    """A missed cell of a two-word key: its log-odds computed (:func:`_miss`) and kept with the key."""
    lo = _miss(nf, k, m)
    o = k * nf.kw
    nf.memo_lo[k] = lo
    nf.memo_key[o] = lo_key
    if nf.kw == 2:
        nf.memo_key[o + 1] = hi_key
    return lo


@njit_shipped(_nrt=False)
def _memo_wide(nf, k, m):
    """:func:`memo_log_odds` of a key of more than two words (``w >= 7``), the key on the stack."""
    kw = nf.kw
    o = k * kw
    key = stack_i64(KEY_WORDS)
    nbhd_key(nf, k, m, key)
    hit = True
    for i in range(kw):
        if nf.memo_key[o + i] != key[i]:
            hit = False
    if hit:
        return nf.memo_lo[k]
    lo = _miss(nf, k, m)
    nf.memo_lo[k] = lo
    for i in range(kw):
        nf.memo_key[o + i] = key[i]
    return lo


@njit_shipped(inline="always")
def memo_log_odds(nf, k, m):
    """``l_k``, the kept value while the cell's neighbourhood key is the kept one, else computed (:func:`_miss`)
    and kept (module docstring). Only the two-word key's check is inlined into the sweeps; a miss and the longer
    keys are calls. Allocates nothing."""
    kw = nf.kw
    if kw <= 2:
        lo_key, hi_key = nbhd_key2(nf, k, m)
        o = k * kw
        if nf.memo_key[o] == lo_key and (kw == 1 or nf.memo_key[o + 1] == hi_key):
            return nf.memo_lo[k]
        return _keep2(nf, k, m, lo_key, hi_key)
    return _memo_wide(nf, k, m)
