"""Sensor-model behaviour the main tests leave open (found by `make mutate`, issue 15): the readings'
dtype carries through ``log_prob``, a hit beyond the far edge of the ray is impossible, and
``GaussianRange.sample`` with random hits draws from the distribution that ``log_prob`` describes."""

import itertools
import math

import numpy as np
import pytest
import torch
from scipy import stats

from ogm_ppl import GaussianRange, PatternMatch


@pytest.mark.parametrize("sensor", [GaussianRange(1.5), GaussianRange(1.5, p_rand=0.1), PatternMatch(0.7)],
                         ids=repr)
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
    return np.array([integral(edges[0], -0.5) + integral(-0.5, edges[1]),
                     *(integral(a, b) for a, b in itertools.pairwise(edges[1:]))])


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
