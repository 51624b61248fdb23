"""ogm_ppl.testing's chi-square test: Pyro's statistic with SciPy's survival function, which is right where
Pyro's ``chi2sf`` is not (statistics above ~160, where its series stops early)."""

import math

import pytest
import torch
from pyro.distributions.testing.gof import multinomial_goodness_of_fit as pyro_gof
from scipy.stats import chi2

from ogm_ppl.testing import PriorContract, multinomial_goodness_of_fit
from ogm_ppl.testing._stats import check_draws


def test_equals_pyros_where_pyros_is_right_and_scipy_where_it_is_not():
    g = torch.Generator().manual_seed(0)
    probs = torch.full((64,), 1 / 64, dtype=torch.float64)
    fair = torch.bincount(torch.multinomial(probs, 20000, replacement=True, generator=g), minlength=64).double()
    assert multinomial_goodness_of_fit(probs, fair) == pytest.approx(pyro_gof(probs, fair), rel=1e-6)
    skew = probs.clone()
    skew[:32] *= 1.25
    skew /= skew.sum()
    biased = torch.bincount(torch.multinomial(skew, 20000, replacement=True, generator=g), minlength=64).double()
    ours = multinomial_goodness_of_fit(probs, biased)
    n = 20000
    stat = float(((biased - n * probs) ** 2 / (n * probs * (1 - probs))).sum())
    assert 160 < stat < 2000 and ours == pytest.approx(chi2.sf(stat, 63), rel=1e-9) and ours < 1e-10
    assert multinomial_goodness_of_fit(torch.tensor([1.0, 0.0]), torch.tensor([5.0, 0.0])) == 1.0
    assert multinomial_goodness_of_fit(torch.tensor([0.5, 0.5, 0.0]), torch.tensor([5.0, 4.0, 1.0])) == math.inf
    with pytest.raises(AssertionError, match="chi-square p-value"):
        check_draws(probs, biased, "biased")


def test_the_prior_contract_fails_a_sampler_ten_percent_off():
    """A prior whose sampler draws occupied cells 10 % too often (its log_prob right) fails the contract's
    sampling check: with Pyro's survival function it passed (chi-square ~220-260 on 63 degrees of freedom)."""
    from ogm_ppl.priors import IndependentPrior

    class Off(IndependentPrior):
        def sample(self, sample_shape=(), generator=None):
            return IndependentPrior(self.lambda_ * 1.1).sample(sample_shape, generator=generator)

    class Contract(PriorContract):
        def make_prior(self, num_cells):
            return Off(torch.linspace(0.2, 0.5, num_cells))

    with pytest.raises(AssertionError):
        Contract().test_samples_follow_log_prob()
