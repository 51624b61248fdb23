"""Map-score edge cases the main tests leave open (found by `make mutate`, issue 15): a single
occupied cell, a truth with no free cell, and an empty mask."""

import warnings

import numpy as np
import pytest

from ogm_ppl.metrics import best_f1, precision_recall, prediction_scores, roc_auc


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
