import math

import pytest
import torch

from ogm_ppl.priors import DataDriven1DPrior, IndependentPrior
from ogm_ppl.testing import PriorContract


class TestUniformPrior(PriorContract):
    def make_prior(self, num_cells):
        return IndependentPrior(0.5, num_cells)


class TestPerCellIndependentPrior(PriorContract):
    def make_prior(self, num_cells):
        return IndependentPrior(torch.linspace(0.1, 0.8, num_cells))


class TestDataDrivenPrior(PriorContract):
    def make_prior(self, num_cells):
        return DataDriven1DPrior(num_cells, start=1)


def test_independent_prior_values_and_log_odds():
    p = IndependentPrior(0.234, 3)
    assert p.log_prob(torch.tensor([1.0, 0.0, 0.0])).item() == pytest.approx(math.log(0.234) + 2 * math.log(0.766))
    torch.testing.assert_close(p.cell_log_odds(), torch.full((3,), math.log(0.234 / 0.766)))
    assert DataDriven1DPrior(4).cell_log_odds() is None


@pytest.mark.parametrize("lam", [0.0, 1.0, -0.2, float("nan")])
def test_bad_lambda(lam):
    with pytest.raises(ValueError, match="lambda_"):
        IndependentPrior(lam, 3)


def test_bad_construction():
    with pytest.raises(ValueError, match="num_cells"):
        IndependentPrior(0.5)
    with pytest.raises(ValueError, match="start"):
        DataDriven1DPrior(4, start=4)


def test_data_driven_prior_support():
    p = DataDriven1DPrior(4, start=1)
    maps = torch.tensor(
        [[0, 0, 0, 0], [0, 0, 0, 1], [0, 0, 1, 1], [0, 1, 1, 1], [1, 1, 1, 1], [0, 1, 0, 1]], dtype=torch.float64
    )
    assert p.log_prob(maps).exp().tolist() == [0.25, 0.25, 0.25, 0.25, 0.0, 0.0]
