import math

import numpy as np
import pytest
import torch
from pyro.distributions.testing.gof import multinomial_goodness_of_fit
from scipy.integrate import quad

from ogm_ppl import GaussianRange, PatternMatch

F = 20


@pytest.mark.parametrize("p_rand", [0.0, 0.2])
@pytest.mark.parametrize("f", [0, 3, 18, 20, 21])  # 21 = no occupied cell within the ray
def test_gaussian_normalises(f, p_rand):
    s = GaussianRange(2.5, p_rand=p_rand)

    def dens(z):
        return math.exp(float(s.log_prob(torch.tensor(z), f, F)))

    breaks = [-0.5, f - 0.5, f + 0.5] if f <= F else [-0.5]
    mass = quad(dens, -np.inf, -0.5)[0] + quad(dens, -0.5, F + 0.5, points=breaks, limit=200)[0]
    p_max = math.exp(float(s.log_prob(torch.tensor(0.0), f, F, is_max=True)))
    assert mass + p_max == pytest.approx(1.0, abs=1e-8)


def test_gaussian_is_the_thesis_density():
    s = GaussianRange(3.0)
    z = torch.tensor([11.0, 7.0, 8.0, 8.0, 5.0, 9.0])
    expected = -0.5 * ((z - 8) / 3) ** 2 - math.log(3 * math.sqrt(2 * math.pi))
    torch.testing.assert_close(s.log_prob(z, 8, 75), expected)
    assert s.log_prob(torch.tensor(8.0), 76, 75) == -math.inf  # nothing to reflect the beam
    assert s.log_prob(torch.tensor(0.0), 76, 75, is_max=True) == 0.0


def test_gaussian_sample_matches_max_range_probability():
    s = GaussianRange(3.0)
    g = torch.Generator().manual_seed(1)
    n = 200_000
    f = torch.full((n,), 18.0)
    z, is_max = s.sample(f, F, generator=g)
    p = math.exp(float(s.log_prob(torch.tensor(0.0), 18, F, is_max=True)))
    se = math.sqrt(p * (1 - p) / n)
    assert abs(is_max.double().mean().item() - p) < 5 * se
    hits = z[~is_max]
    # hits are N(18, 9) truncated above at F + 1/2: mean 18 - sigma * phi(b) / Phi(b)
    b = (F + 0.5 - 18.0) / 3.0
    phi, Phi = math.exp(-b * b / 2) / math.sqrt(2 * math.pi), 0.5 * (1 + math.erf(b / math.sqrt(2)))
    assert abs(hits.mean().item() - (18.0 - 3.0 * phi / Phi)) < 5 * 3.0 / math.sqrt(hits.numel())


def test_pattern_match_normalises_and_samples():
    s = PatternMatch(0.9)
    zs = torch.arange(F + 1, dtype=torch.float64)
    for f in (0, 5, F, F + 1):
        hits = s.log_prob(zs, f, F).exp().sum()
        mx = s.log_prob(torch.tensor(0.0), f, F, is_max=True).exp()
        assert float(hits + mx) == pytest.approx(1.0, abs=1e-12)
    # sampled outcomes follow the pmf (chi-square goodness of fit)
    g = torch.Generator().manual_seed(2)
    z, is_max = s.sample(torch.full((50_000,), 5.0), F, generator=g)
    counts = torch.bincount(torch.where(is_max, F + 1, z.long()), minlength=F + 2).double()
    probs = torch.cat([s.log_prob(zs, 5, F).exp(), s.log_prob(torch.tensor(0.0), 5, F, True).exp()[None]])
    assert multinomial_goodness_of_fit(probs, counts) > 1e-3


@pytest.mark.parametrize("sigma", [0.0, -1.0, float("nan"), float("inf")])
def test_bad_sigma(sigma):
    with pytest.raises(ValueError, match="sigma"):
        GaussianRange(sigma)


@pytest.mark.parametrize("p", [0.0, -0.1, 1.5, float("nan")])
def test_bad_p_occ(p):
    with pytest.raises(ValueError, match="p_occ"):
        PatternMatch(p)


def test_bad_p_rand():
    with pytest.raises(ValueError, match="p_rand"):
        GaussianRange(1.0, p_rand=1.0)
