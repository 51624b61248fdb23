"""Compiled patch Gibbs sweeps over binary maps (Section 4.2; Algorithms 1 and 2), heat bath or metropolised;
the single-cell sweeps are in :mod:`~ogm_ppl.inference._kernels.cell_sweep`.

A sweep updates the patches of a :class:`~ogm_ppl.inference._kernels.patch_state.PatchGeometry` at a list of
anchors on a :class:`~ogm_ppl.inference._kernels.patch_state.PatchState`. Random numbers come in as arrays
drawn outside (from torch's generator), so a run is reproducible from a seed and resumable from a checkpoint.

:func:`patch_sweep` is compiled once per prior bundle type (:mod:`ogm_ppl.priors.compiled`): for priors
whose weights add over cells (independent cells) every update weighs all ``2^L`` configurations in
``O(2^L)`` per ray (:mod:`~ogm_ppl.inference._kernels.additive_sweep`); for the others it weighs the
candidates the prior's kind allows (a tile's sparse support, else all ``2^L``), the rays' terms grouped by
the patch cells they cross (:mod:`~ogm_ppl.inference._kernels.candidate_sweep`). Both end in the one choice
step of :mod:`~ogm_ppl.inference._kernels.choice`. Sweeps allocate their scratch once
(:class:`~ogm_ppl.inference._kernels.patch_rays.RayScratch`,
:class:`~ogm_ppl.priors.compiled.scratch.TileScratch`).
"""

from __future__ import annotations

import numpy as np
from numba.extending import overload

from ogm_ppl._numba_cache import njit_shipped
from ogm_ppl.inference._kernels.additive_sweep import _additive_sweep, additive_patch_log_weights
from ogm_ppl.inference._kernels.candidate_sweep import _candidate_sweep, candidate_log_weights
from ogm_ppl.inference._kernels.patch_state import _next_stamp
from ogm_ppl.priors.compiled import kind_of
from ogm_ppl.priors.compiled.registry import is_additive


def _patch_pass(ps, geo, anchors, prior, u, rule, stamp0, bit_of):
    """Python stand-in of :func:`patch_pass` for numba's overload (not called)."""
    raise NotImplementedError


@overload(_patch_pass)
def _patch_pass_for(ps, geo, anchors, prior, u, rule, stamp0, bit_of):
    if kind_of(prior).additive:
        return lambda ps, geo, anchors, prior, u, rule, stamp0, bit_of: _additive_sweep(
            ps, geo, anchors, prior, u, rule, stamp0, bit_of
        )
    return lambda ps, geo, anchors, prior, u, rule, stamp0, bit_of: _candidate_sweep(
        ps, geo, anchors, prior, u, rule, stamp0, bit_of
    )


@njit_shipped
def patch_pass(ps, geo, anchors, prior, u, rule, stamp0, bit_of):
    """:func:`patch_sweep` with its stamps (``stamp0 .. stamp0 + len(anchors) - 1``, reserved by the caller)
    and the prior scratch's ``bit_of`` (``K`` int64, all -1) given: the building block of the chromatic
    patch sweeps, whose tiles of one colour run it at once (every array it writes is indexed by the patch's
    cells or its rays, so disjoint between tiles; :mod:`~ogm_ppl.inference._kernels.parallel_patch`)."""
    return _patch_pass(ps, geo, anchors, prior, u, rule, stamp0, bit_of)


@njit_shipped
def patch_sweep(ps, geo, anchors, prior, u, rule):
    """One pass of patch updates at ``anchors`` (``n x 2``; Algorithm 1, Algorithm 2 when
    ``rule.p_rand_patch > 0``) with the uniforms ``u`` (``3 x n``: choice, random-patch, acceptance), the
    loop chosen by the prior bundle's type when it compiles. Returns ``(changed, skipped)``."""
    bit_of = np.full(0 if is_additive(prior) else ps.m.shape[0], -1, np.int64)
    return _patch_pass(ps, geo, anchors, prior, u, rule, _next_stamp(ps, anchors.shape[0]), bit_of)


def _patch_log_weights(ps, patch, prior, logw):
    raise NotImplementedError


@overload(_patch_log_weights)
def _patch_log_weights_for(ps, patch, prior, logw):
    if kind_of(prior).additive:
        return lambda ps, patch, prior, logw: additive_patch_log_weights(ps, patch, prior, logw)

    def impl(ps, patch, prior, logw):
        W = logw.shape[0]
        cands = np.arange(W)
        candidate_log_weights(ps, patch, prior, cands, W, logw)
        return W

    return impl


@njit_shipped
def patch_log_weights(ps, patch, prior, logw):
    """``logw[w]``: unnormalised log conditional of every configuration of ``patch`` (``logw``: at least
    ``2^L`` for additive priors, exactly ``2^L`` for the others). Returns ``W``."""
    return _patch_log_weights(ps, patch, prior, logw)
