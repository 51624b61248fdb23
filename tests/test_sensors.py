import itertools
import math

import numpy as np
import pytest
import torch
from scipy import stats
from scipy.integrate import quad

from ogm_ppl import GaussianRange, PatternMatch
from ogm_ppl.testing import multinomial_goodness_of_fit

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


# ----------------------------- dtypes, the far edge, sampling with random hits


@pytest.mark.parametrize("sensor", [GaussianRange(1.5), GaussianRange(1.5, p_rand=0.1), PatternMatch(0.7)], ids=repr)
def test_log_prob_keeps_the_readings_dtype(sensor):
    """float32 readings with Python-number first hits and ray ends give float32 log-probabilities
    (``f`` and ``F`` are cast to the readings' dtype, not to the default float64)."""
    z = torch.tensor([2.0, 4.0, 7.0], dtype=torch.float32)
    lp = sensor.log_prob(z, 3, 6, is_max=torch.tensor([False, False, True]))
    assert lp.dtype == torch.float32
    assert torch.isfinite(lp[:2]).all()


@pytest.mark.parametrize("p_rand", [0.0, 0.2])
def test_a_hit_beyond_the_far_edge_is_impossible(p_rand):
    """A reading past ``F + 1/2`` is reported as max range, never as a hit: log p = -inf as a hit
    (with or without random hits), while the max-range reading keeps its finite probability."""
    s = GaussianRange(2.0, p_rand=p_rand)
    F = 6
    for f in (2, 6, 9):  # a first hit inside the ray, at its end, and none in the ray (f > F)
        assert s.log_prob(F + 0.6, f, F).item() == -math.inf
        assert s.log_prob(F + 3.0, f, F).item() == -math.inf
        assert math.isfinite(s.log_prob(F + 1.0, f, F, is_max=True).item())
    # just inside the far edge a hit is possible
    assert math.isfinite(s.log_prob(F + 0.4, 6, F).item())


def _edges(F: int) -> np.ndarray:
    """Cell bins of the readings, the first one open to the left (Gaussian hits can be negative)."""
    return np.r_[-30.0, np.arange(0.5, F + 1.0, 1.0)]


def _hit_bin_probs(s: GaussianRange, f: float, F: int) -> np.ndarray:
    """P(hit reading in each bin of ``_edges``), integrated from ``exp(log_prob)``."""

    def integral(a: float, b: float) -> float:
        z = torch.linspace(a, b - 1e-12, 4001, dtype=torch.float64)
        return torch.trapezoid(s.log_prob(z, f, F).exp(), z).item()

    edges = _edges(F)
    # the random-hit density starts at -1/2: the first bin is integrated in two pieces
    return np.array(
        [
            integral(edges[0], -0.5) + integral(-0.5, edges[1]),
            *(integral(a, b) for a, b in itertools.pairwise(edges[1:])),
        ]
    )


@pytest.mark.parametrize("f", [4.0, 11.0], ids=["hit-in-ray", "none-in-ray"])
def test_sample_with_random_hits_follows_log_prob(f):
    """``GaussianRange(sigma, p_rand).sample`` against its own ``log_prob``: the share of max-range
    readings, the hit histogram per cell and (with nothing in the ray) uniform random hits on
    ``[-1/2, F + 1/2]``. Seeded, 40,000 draws; tolerances are 5 standard errors."""
    F, n = 9, 40_000
    s = GaussianRange(2.0, p_rand=0.3)
    g = torch.Generator().manual_seed(7)
    y, is_max = s.sample(torch.full((n,), f, dtype=torch.float64), F, generator=g)
    p_max = s.log_prob(F + 1.0, f, F, is_max=True).exp().item()
    se = math.sqrt(p_max * (1 - p_max) / n)
    assert abs(is_max.double().mean().item() - p_max) < 5 * se + 1e-12
    hits = y[~is_max].numpy()
    assert hits.max() <= F + 0.5
    p_bins = _hit_bin_probs(s, f, F)
    assert abs(p_bins.sum() + p_max - 1.0) < 1e-6  # log_prob is a distribution over hits + max range
    counts = np.histogram(hits, bins=_edges(F))[0]
    np.testing.assert_array_less(np.abs(counts - n * p_bins), 5 * np.sqrt(n * p_bins * (1 - p_bins)) + 1)
    if f > F:  # nothing to reflect the beam: every hit is a uniform random one
        assert hits.min() >= -0.5
        assert stats.kstest(hits, stats.uniform(loc=-0.5, scale=F + 1.0).cdf).pvalue > 1e-3
