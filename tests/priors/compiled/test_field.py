"""The pattern field's patch weights: the passes over all ``2^L`` candidates (by row groups for full
rectangles, Gray-code order otherwise) equal the generic per-candidate pass to rounding, on every window
layout a patch can meet (edges, two scales)."""

from __future__ import annotations

import numpy as np
import pytest

from ogm_ppl.priors import PatternFieldPrior
from ogm_ppl.priors.compiled.field_patches import GRAY_RESYNC, _rect_fits, _rect_shape, field_patch_weights
from ogm_ppl.priors.compiled.scratch import tile_scratch


def _assert_full_pass_is_generic(lp, patch, m, ts):
    L = len(patch)
    full = np.arange(1 << L, dtype=np.int64)
    got = np.empty(1 << L)
    field_patch_weights(lp, patch, m, full, 1 << L, got, ts)
    # the generic pass: the same candidates, not in order (a reversed list)
    rev = full[::-1].copy()
    generic = np.empty(1 << L)
    field_patch_weights(lp, patch, m, rev, 1 << L, generic, ts)
    np.testing.assert_allclose(got, generic[::-1], rtol=0, atol=1e-12 * np.abs(generic).max())
    assert (ts.bit_of == -1).all()  # the scratch is left as found


def _field(R, C, two, seed):
    rng = np.random.default_rng(seed)
    prior = PatternFieldPrior(
        (R, C), rng.normal(0, 1.0, 512), w=3, theta2=rng.normal(0, 0.5, 512) if two else None, occupancy=0.3
    )
    return prior.compiled(), (rng.random(R * C) < 0.35).astype(np.uint8)


@pytest.mark.parametrize("two", [False, True])
@pytest.mark.parametrize("shape", [(3, 3), (3, 4), (1, 5), (5, 2)])
def test_row_group_pass_equals_the_generic_pass(two, shape):
    """Full rectangles, at the corners, the edges and inside (the row groups cut by the grid edge)."""
    R, C = 17, 19
    lp, m = _field(R, C, two, 4)
    ts = tile_scratch(R * C, 64)
    h, w = shape
    for r0, c0 in ((0, 0), (R - h, C - w), (5, 7), (R // 2, 0), (1, C - w - 1)):
        patch = np.array([(r0 + a) * C + c0 + b for a in range(h) for b in range(w)], np.int64)
        assert _rect_shape(patch, C) == shape and _rect_fits(3, h, w, ts.memo.shape[0])
        _assert_full_pass_is_generic(lp, patch, m, ts)


@pytest.mark.parametrize("two", [False, True])
def test_gray_pass_equals_the_generic_pass(two):
    """Patches that are not full rectangles (a plus, a rectangle with a pinned cell, one wrapping past the
    last column), and a rectangle whose row groups do not fit the scratch, take the Gray-code pass."""
    R, C = 17, 19
    lp, m = _field(R, C, two, 5)
    small = tile_scratch(R * C, 1)  # room for 2^10 entries: a 3 x 4 row group needs 2^12
    r0, c0 = 6, 7
    plus = np.array(
        [r0 * C + c0 + 1, (r0 + 1) * C + c0, (r0 + 1) * C + c0 + 1, (r0 + 1) * C + c0 + 2, (r0 + 2) * C + c0 + 1],
        np.int64,
    )
    pinned = np.array([(r0 + a) * C + c0 + b for a in range(3) for b in range(3)], np.int64)
    pinned[4] = -1
    wrap = np.array([(r0 + a) * C + C - 2 + b for a in range(2) for b in range(3)], np.int64)  # cols C-2, C-1, C
    wide = np.array([(r0 + a) * C + c0 + b for a in range(3) for b in range(4)], np.int64)
    assert _rect_shape(plus, C) == (0, 0) and _rect_shape(pinned, C) == (0, 0) and _rect_shape(wrap, C) == (0, 0)
    assert _rect_shape(wide, C) == (3, 4) and not _rect_fits(3, 3, 4, small.memo.shape[0])
    assert (1 << 12) > GRAY_RESYNC  # the 3 x 4 patch crosses resynchronisations
    for patch in (plus, pinned, wrap, wide):
        _assert_full_pass_is_generic(lp, patch, m, small)


def test_a_few_candidates_weigh_as_in_the_full_pass():
    """Two candidates (Algorithm 2's pair; fewer than the parents' configurations, so the pooled scale is not
    tabled) get the weights the full pass gives them, to rounding."""
    R, C = 15, 16
    rng = np.random.default_rng(8)
    prior = PatternFieldPrior((R, C), rng.normal(0, 1.0, 512), w=3, theta2=rng.normal(0, 0.5, 512), occupancy=0.3)
    lp = prior.compiled()
    m = (rng.random(R * C) < 0.4).astype(np.uint8)
    ts = tile_scratch(R * C, 64)
    patch = np.array([(6 + a) * C + 7 + b for a in range(3) for b in range(3)], np.int64)
    full = np.empty(512)
    field_patch_weights(lp, patch, m, np.arange(512, dtype=np.int64), 512, full, ts)
    for pair in ([0, 511], [37, 300], [5, 5]):
        got = np.empty(2)
        field_patch_weights(lp, patch, m, np.asarray(pair, np.int64), 2, got, ts)
        np.testing.assert_allclose(got, full[pair], rtol=0, atol=1e-12 * np.abs(full).max())
