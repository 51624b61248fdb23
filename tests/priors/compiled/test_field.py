"""The pattern field's patch weights: the Gray-code pass over all ``2^L`` candidates equals the generic
per-candidate pass to rounding, on every window layout a patch can meet (edges, two scales)."""

from __future__ import annotations

import numpy as np
import pytest

from ogm_ppl.priors import PatternFieldPrior
from ogm_ppl.priors.compiled.field import GRAY_RESYNC, field_patch_weights
from ogm_ppl.priors.compiled.scratch import tile_scratch


@pytest.mark.parametrize("two", [False, True])
@pytest.mark.parametrize("shape", [(3, 3), (3, 4), (1, 5)])
def test_gray_pass_equals_the_generic_pass(two, shape):
    R, C = 17, 19
    rng = np.random.default_rng(4)
    prior = PatternFieldPrior(
        (R, C), rng.normal(0, 1.0, 512), w=3, theta2=rng.normal(0, 0.5, 512) if two else None, occupancy=0.3
    )
    lp = prior.compiled()
    m = (rng.random(R * C) < 0.35).astype(np.uint8)
    ts = tile_scratch(R * C, 64)
    h, w = shape
    L = h * w
    assert L < 7 or (1 << L) > GRAY_RESYNC  # the larger patches cross resynchronisations
    full = np.arange(1 << L, dtype=np.int64)
    for r0, c0 in ((0, 0), (R - h, C - w), (5, 7), (R // 2, 0)):
        patch = np.array([(r0 + a) * C + c0 + b for a in range(h) for b in range(w)], np.int64)
        gray = np.empty(1 << L)
        field_patch_weights(lp, patch, m, full, 1 << L, gray, ts)
        # the generic pass: the same candidates, not in order (a reversed list)
        rev = full[::-1].copy()
        generic = np.empty(1 << L)
        field_patch_weights(lp, patch, m, rev, 1 << L, generic, ts)
        np.testing.assert_allclose(gray, generic[::-1], rtol=0, atol=1e-12 * np.abs(generic).max())
        assert (ts.bit_of == -1).all()  # the scratch is left as found


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
