"""The compiled conditionals of each bundle kind, chosen by the bundle's type when a kernel compiles.

A kind registers its numba-compilable functions once (:func:`register`); the generic entry points below
are ``numba.extending.overload``\\ s that hand the kernels the registered function of the bundle type they
are compiled for (inlined, so a sweep specialised for one kind runs that kind's conditional in its loop):

* :func:`cell_log_odds` ``(prior, k, m)`` — ``log p(m_k = 1, m_-k) - log p(m_k = 0, m_-k)`` (``nan`` if
  both are impossible): single-cell Gibbs, ICM; it must not allocate (the single-cell sweeps compile
  without numba's runtime, :func:`~ogm_ppl.inference._kernels.cell_sweep.sweep`);
* :func:`patch_prior_weights` ``(prior, patch, m, cands, n, out, ts)`` — ``out[j] = log p(patch = cands[j],
  rest)`` up to a constant in ``j`` (bit ``b`` of a candidate = the ``b``-th live cell of ``patch``);
* :func:`patch_candidates` ``(prior, r0, c0, h, w, patch, n_live, pinned, m, cands, cand_lp)`` — the
  configurations a patch update weighs (default: all ``2^n_live``; a table prior whose tiles are the
  patches: the tile's sparse support); returns ``(count, tag)``, ``tag >= 0`` naming the kind's own
  sparse case for :func:`candidate_weights`;
* :func:`candidate_weights` ``(prior, patch, m, cands, n, tag, cand_lp, out, ts)`` — the prior weights of
  the candidates of :func:`patch_candidates` (default: :func:`patch_prior_weights`);
* :func:`scratch_capacity` ``(prior, L)`` — the size of the :class:`~ogm_ppl.priors.compiled.scratch.TileScratch`
  a kind's patch weights need for ``L``-cell patches (default 1);
* :func:`restricted` ``(prior, tag)`` — ``True`` when the candidates of :func:`patch_candidates` with this
  ``tag`` are only part of the configurations with prior mass (a backed-off table's counted
  configurations): the sweep then draws among them only when the current configuration is one of them,
  and adds the kind's escape move (default ``False``);
* :func:`escape_proposal` ``(prior, tag, patch, m, u, pair_lp)`` — the escape move's proposal from the
  uniform ``u``: ``(prop, log q(cur) - log q(prop))`` (``prop = -1``: none), the kind's own weight of the
  current and the proposed configuration in ``pair_lp[0], pair_lp[1]`` (the ``cand_lp`` of
  :func:`candidate_weights` with this ``tag``); only called where :func:`restricted` holds;
* :func:`shared_weights` ``(prior)`` — how many keys :func:`shared_weights_key` can return (default 0);
* :func:`shared_weights_key` ``(prior, r0, c0, h, w, n_live)`` — a key ``>= 0`` when the candidates of
  :func:`patch_candidates` for the patch at ``(r0, c0)`` (``h x w``, ``n_live`` live cells) and their
  :func:`candidate_weights` depend on the key alone, not on the rest of the map, and are not
  :func:`restricted` (a patch table without a border: every full tile of one segment weighs the same
  configurations alike), so a sweep may compute them once per key; ``-1`` otherwise (the default);
* :func:`is_additive` ``(prior)`` — ``True`` when a configuration's prior weight is the sum of its cells'
  :func:`cell_log_odds`, whatever the rest of the map (independent cells): patch kernels then weigh all
  ``2^L`` configurations in ``O(2^L)``;
* :func:`patch_allocates` ``(prior)`` — ``False`` when the kind's patch conditionals (:func:`patch_candidates`,
  :func:`candidate_weights`, :func:`patch_prior_weights`, :func:`escape_proposal`) allocate nothing: the
  patch sweep then runs its loop without numba's runtime, which otherwise counts the references of every
  bundle array at each inlined call (default ``True``, the loop keeps the runtime; a kind that declares
  ``False`` and allocates fails to compile with "NRT required but not enabled").

Each entry point is also callable from Python (slowly, for tests).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

import numpy as np
from numba.extending import overload

__all__ = [
    "Kind",
    "candidate_weights",
    "cell_log_odds",
    "escape_proposal",
    "is_additive",
    "kind_of",
    "patch_allocates",
    "patch_candidates",
    "patch_prior_weights",
    "register",
    "registered",
    "restricted",
    "scratch_capacity",
    "shared_weights",
    "shared_weights_key",
]


class Kind(NamedTuple):
    """The compiled functions of one bundle kind (plain Python functions numba compiles inline)."""

    cell_log_odds: Callable
    patch_prior_weights: Callable
    patch_candidates: Callable
    candidate_weights: Callable
    scratch_capacity: Callable
    additive: bool
    restricted: Callable
    escape_proposal: Callable
    shared_weights: Callable
    shared_weights_key: Callable
    patch_allocates: bool = True


_KINDS: dict[type, Kind] = {}


def _dense_candidates(prior, r0, c0, h, w, patch, n_live, pinned, m, cands, cand_lp):
    if n_live > 62 or (np.int64(1) << n_live) > cands.shape[0]:
        return np.int64(-1), np.int64(-1)
    W = np.int64(1) << n_live
    for j in range(W):
        cands[j] = j
    return W, np.int64(-1)


def _no_scratch(prior, L):
    return 1


def _unrestricted(prior, tag):
    return False


def _no_shared(prior):
    return 0


def _no_shared_key(prior, r0, c0, h, w, n_live):
    return -1


def _no_escape(prior, tag, patch, m, u, pair_lp):
    return np.int64(-1), 0.0


def register(
    bundle: type,
    *,
    cell_log_odds: Callable,
    patch_prior_weights: Callable,
    candidate_weights: Callable,
    patch_candidates: Callable | None = None,
    scratch_capacity: Callable | None = None,
    additive: bool = False,
    restricted: Callable | None = None,
    escape_proposal: Callable | None = None,
    shared_weights: Callable | None = None,
    shared_weights_key: Callable | None = None,
    patch_allocates: bool = True,
) -> None:
    """Register the compiled conditionals of the bundle class ``bundle`` (see the module docstring for each
    function's signature and meaning; the optional ones default to the dense, scratch-free versions)."""
    _KINDS[bundle] = Kind(
        cell_log_odds,
        patch_prior_weights,
        patch_candidates or _dense_candidates,
        candidate_weights,
        scratch_capacity or _no_scratch,
        bool(additive),
        restricted or _unrestricted,
        escape_proposal or _no_escape,
        shared_weights or _no_shared,
        shared_weights_key or _no_shared_key,
        bool(patch_allocates),
    )


def registered() -> tuple[type, ...]:
    """The registered bundle classes."""
    return tuple(_KINDS)


def kind_of(prior) -> Kind:
    """The registered functions of a bundle (a Python object) or of its numba type."""
    cls = getattr(prior, "instance_class", None) or type(prior)
    try:
        return _KINDS[cls]
    except KeyError:
        raise TypeError(f"no compiled prior kind is registered for {cls.__name__}") from None


def _registered(prior, name):
    kind = _KINDS.get(getattr(prior, "instance_class", None))
    return None if kind is None else getattr(kind, name)


def cell_log_odds(prior, k, m):
    return kind_of(prior).cell_log_odds(prior, k, m)


def patch_prior_weights(prior, patch, m, cands, n, out, ts):
    return kind_of(prior).patch_prior_weights(prior, patch, m, cands, n, out, ts)


def patch_candidates(prior, r0, c0, h, w, patch, n_live, pinned, m, cands, cand_lp):
    return kind_of(prior).patch_candidates(prior, r0, c0, h, w, patch, n_live, pinned, m, cands, cand_lp)


def candidate_weights(prior, patch, m, cands, n, tag, cand_lp, out, ts):
    return kind_of(prior).candidate_weights(prior, patch, m, cands, n, tag, cand_lp, out, ts)


def scratch_capacity(prior, L):
    return kind_of(prior).scratch_capacity(prior, L)


def is_additive(prior):
    return kind_of(prior).additive


def patch_allocates(prior) -> bool:
    return kind_of(prior).patch_allocates


def restricted(prior, tag):
    return kind_of(prior).restricted(prior, tag)


def escape_proposal(prior, tag, patch, m, u, pair_lp):
    return kind_of(prior).escape_proposal(prior, tag, patch, m, u, pair_lp)


def shared_weights(prior):
    return kind_of(prior).shared_weights(prior)


def shared_weights_key(prior, r0, c0, h, w, n_live):
    return kind_of(prior).shared_weights_key(prior, r0, c0, h, w, n_live)


# numba checks that an implementation's signature is the overload's, so each typer spells it out
@overload(cell_log_odds, inline="always")
def _cell_log_odds(prior, k, m):
    return _registered(prior, "cell_log_odds")


@overload(patch_prior_weights, inline="always")
def _patch_prior_weights(prior, patch, m, cands, n, out, ts):
    return _registered(prior, "patch_prior_weights")


@overload(patch_candidates, inline="always")
def _patch_candidates(prior, r0, c0, h, w, patch, n_live, pinned, m, cands, cand_lp):
    return _registered(prior, "patch_candidates")


@overload(candidate_weights, inline="always")
def _candidate_weights(prior, patch, m, cands, n, tag, cand_lp, out, ts):
    return _registered(prior, "candidate_weights")


@overload(scratch_capacity, inline="always")
def _scratch_capacity(prior, L):
    return _registered(prior, "scratch_capacity")


@overload(restricted, inline="always")
def _restricted(prior, tag):
    return _registered(prior, "restricted")


@overload(escape_proposal, inline="always")
def _escape_proposal(prior, tag, patch, m, u, pair_lp):
    return _registered(prior, "escape_proposal")


@overload(shared_weights, inline="always")
def _shared_weights(prior):
    return _registered(prior, "shared_weights")


@overload(shared_weights_key, inline="always")
def _shared_weights_key(prior, r0, c0, h, w, n_live):
    return _registered(prior, "shared_weights_key")


@overload(is_additive, inline="always")
def _is_additive(prior):
    kind = _KINDS.get(getattr(prior, "instance_class", None))
    if kind is None:
        return None
    if kind.additive:
        return lambda prior: True
    return lambda prior: False
