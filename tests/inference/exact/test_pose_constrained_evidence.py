"""The log evidence ``log p(z)`` of the pose-constrained 1D solution (``pose_constrained_1d``, Section
2.3.1) equals brute force over every map, under the data-driven prior (whose normaliser has the
``log(n + 1)`` term) and an independent prior with a different ``lambda`` per cell."""

import pytest
import torch

from ogm_ppl.inference.exact import brute_force, pose_constrained_1d
from ogm_ppl.priors import DataDriven1DPrior, IndependentPrior

from .test_exact import model_1d as exact_model_1d


@pytest.mark.parametrize(
    "K, readings, start",
    [(3, (2.0,), 1), (5, (3.0, 4.0), 1), (7, (2.0, 6.0, 5.0), 1), (8, (5.0, 5.0, 7.0), 3), (10, (9.0, 1.0), 2)],
)
def test_data_driven_log_evidence_matches_brute_force(K, readings, start):
    for prior in (DataDriven1DPrior(K + 1, start=start), IndependentPrior(torch.linspace(0.15, 0.7, K + 1))):
        model = exact_model_1d(K, readings, prior=prior)
        bf, pc = brute_force(model), pose_constrained_1d(model)
        assert pc.log_evidence == pytest.approx(bf.log_evidence, abs=1e-9), prior
