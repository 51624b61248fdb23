"""Contract checks every sensor model must pass: ``log_prob`` is normalised over ranges and vectorised."""

from __future__ import annotations

import math

import torch

__all__ = ["SensorContract"]


class SensorContract:
    """Mix into a pytest class and define ``make_sensor()``."""

    F = 12
    discrete = False  # True for sensors whose hits are whole cells (PatternMatch)

    def make_sensor(self):  # pragma: no cover - to be provided
        raise NotImplementedError

    def test_log_prob_normalises(self):
        from scipy.integrate import quad

        s = self.make_sensor()
        F = self.F
        for f in (0, F // 2, F, F + 1):
            p_max = math.exp(float(s.log_prob(torch.tensor(0.0), f, F, is_max=True)))
            if self.discrete:
                hits = s.log_prob(torch.arange(F + 1, dtype=torch.float64), f, F).exp().sum().item()
            else:

                def dens(z, f=f):
                    return math.exp(float(s.log_prob(torch.tensor(z), f, F)))

                pts = [-0.5, f - 0.5, f + 0.5] if f <= F else [-0.5]
                hits = quad(dens, -math.inf, -0.5)[0] + quad(dens, -0.5, F + 0.5, points=pts, limit=200)[0]
            assert abs(hits + p_max - 1.0) < 1e-7, (f, hits, p_max)

    def test_log_prob_is_vectorised(self):
        s = self.make_sensor()
        z = torch.arange(6, dtype=torch.float64)[:, None]
        f = torch.arange(8)[None, :]
        out = s.log_prob(z, f, self.F)
        assert out.shape == (6, 8)
        assert not torch.isnan(out).any()
        for i in range(6):
            for j in range(8):
                assert torch.equal(out[i, j], s.log_prob(z[i, 0], int(f[0, j]), self.F))
