import math

import numpy as np
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


@pytest.mark.parametrize("shape", [(-4, 4), (0, 4), (4.5, 4), (4, 4, 4)])
def test_a_prior_shape_that_is_no_grid_is_refused(shape):
    from ogm_ppl.priors import MRFPrior

    with pytest.raises(ValueError, match="grid shape"):
        MRFPrior(shape)


def test_a_prior_shape_given_as_an_array_is_read_as_a_shape():
    from ogm_ppl.priors import MRFPrior

    assert (MRFPrior(np.array([4, 5])).rows, MRFPrior(np.array([4, 5])).cols) == (4, 5)
    assert MRFPrior(torch.tensor([3, 2])).num_cells == 6


def test_independent_prior_refuses_a_cell_count_below_one():
    with pytest.raises(ValueError, match="num_cells must be a whole number >= 1, got -3"):
        IndependentPrior(0.5, -3)


def test_the_contract_fails_a_prior_that_forgot_its_outside_occupancy():
    """A prior of cells occupied with probability 0.2 that keeps the base class's outside_occupancy (0.5)
    fails the contract (the model would fill the space past the grid's edge at 0.5)."""
    import pytest

    from ogm_ppl.priors import IndependentPrior
    from ogm_ppl.priors.base import MapPrior

    class Forgot(IndependentPrior):
        outside_occupancy = MapPrior.outside_occupancy

    class Contract(PriorContract):
        def make_prior(self, num_cells):
            return Forgot(0.2, num_cells)

    with pytest.raises(AssertionError, match="override outside_occupancy"):
        Contract().test_outside_occupancy_is_the_priors_own()
