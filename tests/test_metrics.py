import math
import warnings

import numpy as np
import pytest
import torch
from hypothesis import given
from hypothesis import strategies as st

from ogm_ppl.metrics import (
    best_f1,
    cross_entropy,
    cross_entropy_per_cell,
    kl_divergence,
    kl_per_cell,
    near_mapped_mask,
    precision_recall,
    prediction_scores,
    roc_auc,
)

probs = st.lists(st.floats(0.0, 1.0), min_size=1, max_size=30)


def test_kl_closed_form():
    expected = 0.3 * math.log(0.3 / 0.6) + 0.7 * math.log(0.7 / 0.4)
    assert float(kl_per_cell([0.3], [0.6])[0]) == pytest.approx(expected, abs=1e-15)
    h = -(0.3 * math.log(0.6) + 0.7 * math.log(0.4))
    assert float(cross_entropy([0.3, 0.0], [0.6, 0.0])) == pytest.approx(h, abs=1e-15)


@given(probs, st.data())
def test_kl_nonnegative_and_cross_entropy_decomposes(p, data):
    q = data.draw(st.lists(st.floats(1e-6, 1 - 1e-6), min_size=len(p), max_size=len(p)))
    kl = kl_per_cell(p, q)
    assert torch.all(kl >= -1e-12)
    assert float(kl_divergence(p, p)) == pytest.approx(0.0, abs=1e-12)
    pt = torch.tensor(p)
    entropy = -(torch.special.xlogy(pt, pt) + torch.special.xlogy(1 - pt, 1 - pt))
    torch.testing.assert_close(cross_entropy_per_cell(p, q), kl + entropy)


def test_impossible_estimate_is_infinite_and_masks_apply():
    assert math.isinf(float(cross_entropy([0.5], [0.0])))
    assert float(kl_divergence([0.5, 0.2], [0.0, 0.2], mask=[False, True])) == 0.0


@pytest.mark.parametrize("bad", [[np.nan, 0.5], [1.2, 0.5], [-0.1, 0.5]])
def test_bad_probabilities(bad):
    with pytest.raises(ValueError, match="q"):
        cross_entropy([0.5, 0.5], bad)


def test_precision_recall_by_hand():
    est, truth = [0.9, 0.6, 0.2, 0.7], [1, 0, 1, 0]
    c = precision_recall(est, truth, thresholds=[0.5, 0.95, 0.1])
    np.testing.assert_allclose(c.precision, [1 / 3, 1.0, 0.5])
    np.testing.assert_allclose(c.recall, [0.5, 0.0, 1.0])
    np.testing.assert_allclose(c.f1, [0.4, 0.0, 2 / 3])
    c = precision_recall(est, truth, thresholds=[0.5], mask=[True, False, True, False])
    assert c.precision[0] == 1.0 and c.recall[0] == 0.5
    f1, thr = best_f1(est, truth, thresholds=[0.5, 0.95, 0.1])
    assert f1 == pytest.approx(2 / 3) and thr == 0.1


def test_roc_auc_is_the_pairwise_statistic():
    rng = np.random.default_rng(0)
    est = rng.integers(0, 5, 200) / 4.0  # many ties
    truth = rng.random(200) < 0.3
    pos, neg = est[truth], est[~truth]
    pairs = (pos[:, None] > neg[None, :]).mean() + 0.5 * (pos[:, None] == neg[None, :]).mean()
    assert roc_auc(est, truth) == pytest.approx(pairs, abs=1e-12)
    assert roc_auc([0.1, 0.9], [0, 1]) == 1.0 and roc_auc([0.9, 0.1], [0, 1]) == 0.0
    with pytest.raises(ValueError, match="both"):
        roc_auc([0.1, 0.2], [0, 0])


def test_near_mapped_mask_matches_brute_force():
    rng = np.random.default_rng(1)
    mapped = rng.random((30, 40)) < 0.02
    got = near_mapped_mask(mapped, 10.0)
    rr, cc = np.nonzero(mapped)
    R, C = np.mgrid[0:30, 0:40]
    d2 = ((R[..., None] - rr) ** 2 + (C[..., None] - cc) ** 2).min(-1)
    np.testing.assert_array_equal(got, d2 <= 100)


def test_shape_mismatch():
    with pytest.raises(ValueError, match="cells"):
        precision_recall([0.5, 0.5], [1, 0, 1])


def test_prediction_scores_against_hand_computed_values():
    from ogm_ppl.metrics import (
        brier_score,
        expected_calibration_error,
        nll_bits,
        occupied_iou,
        prediction_scores,
    )

    q = np.array([0.9, 0.2, 0.5, 0.75])
    m = np.array([True, False, True, False])
    assert nll_bits(q, m) == pytest.approx(-(np.log2(0.9) + np.log2(0.8) + np.log2(0.5) + np.log2(0.25)) / 4)
    assert brier_score(q, m) == pytest.approx((0.01 + 0.04 + 0.25 + 0.5625) / 4)
    # bins of 0.1: {0.2}: |0.2 - 0|, {0.5}: |0.5 - 1|, {0.75}: |0.75 - 0|, {0.9}: |0.9 - 1|
    assert expected_calibration_error(q, m) == pytest.approx((0.2 + 0.5 + 0.75 + 0.1) / 4)
    # called occupied at 0.5: cells 0 and 3 (0.5 is not above 0.5); truth 0 and 2: IoU = 1 / 3
    assert occupied_iou(q, m) == pytest.approx(1 / 3)
    assert occupied_iou(q, m, unknown=[False, False, False, True]) == pytest.approx(1 / 2)
    assert nll_bits(np.array([1.0, 0.0]), np.array([True, False])) == pytest.approx(0.0, abs=1e-5)
    s = prediction_scores(q, m, mask=np.array([True, True, False, True]))
    assert s["cells"] == 3 and s["auc"] == pytest.approx(1.0)


# ----------------------- a single occupied cell, one class only, an empty mask


def test_recall_with_a_single_occupied_cell():
    """One occupied cell, found at every threshold below 0.9: recall 1 there, 0 above; the best F1 is
    1 (precision 1: the free cells score at most 0.2)."""
    est = np.array([0.9, 0.1, 0.2, 0.05])
    tru = np.array([True, False, False, False])
    c = precision_recall(est, tru, thresholds=[0.15, 0.5, 0.95])
    np.testing.assert_array_equal(c.tp, [1, 1, 0])
    np.testing.assert_array_equal(c.recall, [1.0, 1.0, 0.0])
    np.testing.assert_allclose(c.precision, [0.5, 1.0, 1.0])
    np.testing.assert_allclose(c.f1, [2 / 3, 1.0, 0.0])
    assert best_f1(est, tru) == (1.0, 0.2)  # the first threshold above every free cell's score


@pytest.mark.parametrize("truth", [[True, True, True], [False, False, False]], ids=["no-free", "no-occupied"])
def test_roc_auc_needs_both_classes(truth):
    with pytest.raises(ValueError, match="both occupied and free"):
        roc_auc(np.array([0.2, 0.5, 0.9]), np.array(truth))


def test_empty_mask_gives_nan_scores_quietly():
    """Every score of an empty mask is NaN, without numpy's empty-slice or 0/0 warnings."""
    est, tru = np.array([0.2, 0.7, 0.9]), np.array([False, True, True])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        out = prediction_scores(est, tru, mask=np.zeros(3, dtype=bool))
    assert out["cells"] == 0
    assert all(np.isnan(v) for k, v in out.items() if k != "cells")


def test_best_f1_of_a_mask_without_occupied_cells_is_undefined():
    """No occupied cell under the mask: recall is undefined, so best F1 is NaN (as AUC is), not the 0 that a
    mean over maps would count against every method alike; one occupied cell makes both defined again."""
    est, tru = np.array([0.2, 0.7, 0.9]), np.array([False, False, False])
    out = prediction_scores(est, tru)
    assert np.isnan(out["best_f1"]) and np.isnan(out["auc"]) and out["nll_bits"] > 0
    out = prediction_scores(est, np.array([False, False, True]))
    assert out["best_f1"] == 1.0 and out["auc"] == 1.0


# ----------------------- reliability diagrams


def test_reliability_against_hand_computed_bins():
    """Six cells in 10 bins: 0.05 -> bin 0; 0.15, 0.12 -> bin 1; 0.55 -> bin 5; 0.95 and 1.0 -> bin 9 (the last
    bin is closed). ECE = (|0.05 - 0| + |0.27 - 1| + |0.55 - 1| + |1.95 - 1|) / 6."""
    from ogm_ppl.metrics import expected_calibration_error, reliability

    q = np.array([0.05, 0.15, 0.12, 0.55, 0.95, 1.0])
    m = np.array([False, True, False, True, True, False])
    r = reliability(q, m)
    np.testing.assert_array_equal(r.edges, np.linspace(0, 1, 11))
    np.testing.assert_array_equal(r.count, [1, 2, 0, 0, 0, 1, 0, 0, 0, 2])
    np.testing.assert_allclose(r.sum_q, [0.05, 0.27, 0, 0, 0, 0.55, 0, 0, 0, 1.95], atol=1e-15)
    np.testing.assert_array_equal(r.sum_occupied, [0, 1, 0, 0, 0, 1, 0, 0, 0, 1])
    np.testing.assert_allclose(r.mean_q[[0, 1, 5, 9]], [0.05, 0.135, 0.55, 0.975])
    np.testing.assert_allclose(r.occupied[[0, 1, 5, 9]], [0.0, 0.5, 1.0, 0.5])
    assert np.isnan(r.mean_q[2]) and np.isnan(r.occupied[2])
    assert r.ece == pytest.approx(2.18 / 6)
    assert expected_calibration_error(q, m) == pytest.approx(2.18 / 6)
    # two bins: {0.05, 0.15, 0.12} and {0.55, 0.95, 1.0}: (|0.32 - 1| + |2.5 - 2|) / 6
    assert reliability(q, m, bins=2).ece == pytest.approx(1.18 / 6)
    # one bin: |mean q - mean m|
    assert reliability(q, m, bins=1).ece == pytest.approx(abs(q.mean() - m.mean()))
    # a mask keeps cells 1 and 4 only
    rm = reliability(q, m, mask=[False, True, False, False, True, False])
    assert rm.count.sum() == 2 and rm.ece == pytest.approx((0.85 + 0.05) / 2)


def test_reliability_pools_by_adding_and_round_trips():
    from ogm_ppl.metrics import Reliability, reliability

    rng = np.random.default_rng(1)
    q, m = rng.random(50), rng.random(50) < 0.3
    whole = reliability(q, m)
    parts = Reliability.pooled([reliability(q[:20], m[:20]), reliability(q[20:], m[20:])])
    np.testing.assert_array_equal(parts.count, whole.count)
    np.testing.assert_allclose(parts.sum_q, whole.sum_q)
    assert parts.ece == pytest.approx(whole.ece)
    back = Reliability.from_dict(whole.to_dict())
    np.testing.assert_array_equal(back.count, whole.count)
    assert back.ece == whole.ece
    with pytest.raises(ValueError, match="B \\+ 1 increasing edges"):
        Reliability.from_dict({**whole.to_dict(), "count": [1, 2]})
    with pytest.raises(ValueError, match="not a reliability record"):
        Reliability.from_dict({"edges": [0, 1]})
    with pytest.raises(ValueError, match="same bins"):
        Reliability.pooled([whole, reliability(q, m, bins=4)])


def test_reliability_refuses_bad_input_and_an_empty_mask_is_nan():
    from ogm_ppl.metrics import reliability

    with pytest.raises(ValueError, match=r"\[0, 1\]"):
        reliability([0.2, 1.5], [True, False])
    with pytest.raises(ValueError, match="bins must be >= 1"):
        reliability([0.2], [True], bins=0)
    r = reliability([0.2, 0.7], [False, True], mask=[False, False])
    assert r.count.sum() == 0 and math.isnan(r.ece)


def test_saturated_cells_counts_marginals_within_eps_of_0_or_1():
    from ogm_ppl.metrics import saturated_cells

    q = np.array([0.0, 1e-7, 0.5, 1 - 1e-7, 1.0, 0.3])
    assert saturated_cells(q) == 4
    assert saturated_cells(q, mask=np.array([1, 0, 1, 0, 0, 1], bool)) == 1
    assert saturated_cells(q, eps=1e-8) == 2
