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


@pytest.mark.parametrize("K, readings, start", [(5, (3.0, 4.0), 1), (8, (5.0, 5.0, 7.0), 3), (10, (9.0, 1.0), 2)])
def test_data_driven_exact_path_is_float64_to_1e12(K, readings, start):
    """The data-driven prior's log-probabilities and the pose-constrained solution are float64: the log
    evidence and every cell marginal equal brute force to 1e-12 (float32 would be off by ~1e-7), also
    under torch's own default dtype (float32; the suite's conftest sets float64, which hid this)."""
    import math

    torch.set_default_dtype(torch.float32)  # the conftest fixture restores it
    prior = DataDriven1DPrior(K + 1, start=start)
    maps = prior.sample((4,), generator=torch.Generator().manual_seed(0))
    lp = prior.log_prob(maps)
    assert lp.dtype == torch.float64 and torch.all(lp == -math.log(prior.n + 1))
    model = exact_model_1d(K, readings, prior=prior)
    bf, pc = brute_force(model), pose_constrained_1d(model)
    assert abs(pc.log_evidence - bf.log_evidence) < 1e-12
    assert pc.marginals.dtype == torch.float64
    torch.testing.assert_close(pc.marginals, bf.marginals, rtol=0, atol=1e-12)
