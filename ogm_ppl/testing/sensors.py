r"""Contract checks every sensor model must pass, as a pytest mixin::

    class TestMySensor(SensorContract):
        discrete = False                  # True for sensors whose hits are whole cells (PatternMatch)
        def make_sensor(self):
            return MySensor(sigma=2.0)

On a ray of ``F`` cells (:mod:`ogm_ppl.sensors`: a hit ``z`` in kappa units, the first occupied cell ``f``,
``f > F + 1/2`` meaning none for a continuous sensor, ``f > F`` for a discrete one):

* **its kind of range**: ``continuous_range`` is ``True`` exactly for a continuous sensor (the model scores a
  continuous sensor's readings at their range, a discrete one's at their cell);
* **normalised**: on rays of every length in ``ray_lengths`` (1, ``F`` and 100 cells), for first hits at whole
  cells, between cells, just past the ray's last cell and beyond the ray, the hits (integrated by quadrature,
  or summed over cells) and the max-range reading carry probability 1 (to ``1e-7``);
* **vectorised**: one call over a grid of readings, first hits (beyond the ray included), max-range flags and
  ray lengths gives, element by element, what single calls give (to ``1e-12`` relative);
* **its draws follow** ``log_prob``: ``num_samples`` readings from :meth:`sample` per first hit, binned by
  cell (hits) plus the max-range reading, against the probabilities ``log_prob`` gives those bins
  (chi-square, bins of expected count below 5 pooled, p-value above ``1e-3``; fixed seed). ``Predictive``
  and :meth:`~ogm_ppl.models.OccupancyModel.simulate_readings` draw readings through it; a sensor that cannot
  draw (``sample`` raises ``NotImplementedError``) fails unless its contract class sets ``can_sample = False``.
"""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
import torch

from ogm_ppl.testing._stats import check_draws

__all__ = ["SensorContract"]


class SensorContract:
    """Mix into a pytest class and define ``make_sensor()`` (module docstring)."""

    F = 12  #: the ray length of the vectorisation and sampling checks
    ray_lengths: tuple[int, ...] = (1, 12, 100)  #: ray lengths of the normalisation check
    discrete = False  # True for sensors whose hits are whole cells (PatternMatch)
    can_sample = True  #: False: ``sample`` is not implemented (Predictive cannot draw the sensor's readings)
    num_samples = 20000  #: draws per first hit in the sampling check

    def make_sensor(self):  # pragma: no cover - to be provided
        raise NotImplementedError

    def _first_hits(self, F: int | None = None) -> tuple[float, ...]:
        F = self.F if F is None else F
        if self.discrete:
            return (0, 3, F // 2, F, F + 1)
        # between cells (2D entry distances are not whole), just past the last cell (still a hit: f <= F + 1/2)
        return (0.0, 2.37, F / 2, float(F), F + 0.25, F + 1.0)

    def _density(self, s, f: float, F: int):
        def dens(z: float) -> float:
            return float(torch.exp(s.log_prob(torch.tensor(z, dtype=torch.float64), f, F)))

        return dens

    def _hit_mass(self, s, f: float, a: float, b: float, F: int | None = None) -> float:
        """Probability of a hit in ``[a, b]`` on a ray of ``F`` cells (continuous sensors)."""
        F = self.F if F is None else F
        from scipy.integrate import quad

        pts = sorted({p for p in (f - 0.5, f, f + 0.5, -0.5) if a < p < b})
        kw = {"points": pts, "limit": 200} if pts and math.isfinite(a) and math.isfinite(b) else {"limit": 200}
        return quad(self._density(s, f, F), a, b, **kw)[0]

    def test_declares_its_kind_of_range(self):
        s = self.make_sensor()
        continuous = bool(getattr(s, "continuous_range", False))
        assert continuous == (not self.discrete), (
            f"{type(s).__name__}.continuous_range is {continuous}, but the contract's discrete = {self.discrete}: "
            "a sensor of continuous ranges sets continuous_range = True (the model then scores its readings at "
            "their range), a sensor of whole cells leaves it False"
        )

    def test_log_prob_normalises(self):
        s = self.make_sensor()
        for F in self.ray_lengths:
            for f in self._first_hits(F):
                p_max = math.exp(float(s.log_prob(torch.tensor(0.0), f, F, is_max=True)))
                if self.discrete:
                    hits = s.log_prob(torch.arange(F + 1, dtype=torch.float64), f, F).exp().sum().item()
                else:
                    hits = self._hit_mass(s, f, -math.inf, -0.5, F) + self._hit_mass(s, f, -0.5, F + 0.5, F)
                assert abs(hits + p_max - 1.0) < 1e-7, (
                    f"ray of {F} cells, first hit {f}: hits {hits} + max range {p_max} != 1"
                )

    def test_log_prob_is_vectorised(self):
        s = self.make_sensor()
        F = self.F
        g = torch.Generator().manual_seed(0)
        if self.discrete:
            z = torch.arange(6, dtype=torch.float64)[:, None]
            f = torch.arange(F + 3, dtype=torch.float64)[None, :]
        else:
            z = torch.linspace(-0.7, F + 0.4, 6, dtype=torch.float64)[:, None]
            f = torch.cat([torch.arange(F + 3, dtype=torch.float64), torch.tensor([2.37, F + 0.25])])[None, :]
        Fs = torch.tensor([F, F, F - 2, F - 2, F + 3, F], dtype=torch.float64)[:, None]  # rays of other lengths
        is_max = torch.rand(z.shape[0], f.shape[1], generator=g) < 0.3
        out = s.log_prob(z, f, Fs, is_max=is_max)
        assert out.shape == (z.shape[0], f.shape[1])
        assert not torch.isnan(out).any()
        for i in range(z.shape[0]):
            for j in range(f.shape[1]):
                one = torch.as_tensor(s.log_prob(z[i, 0], f[0, j], Fs[i, 0], is_max=is_max[i, j]), dtype=out.dtype)
                same = bool(out[i, j] == one) or abs(float(out[i, j] - one)) <= 1e-12 * abs(float(one))
                assert same, (
                    f"element ({i}, {j}): z {float(z[i, 0])}, f {float(f[0, j])}, F {float(Fs[i, 0])}, "
                    f"is_max {bool(is_max[i, j])}: {float(out[i, j])} in one call, {float(one)} alone"
                )

    def test_samples_follow_log_prob(self):
        s = self.make_sensor()
        F, n = self.F, int(self.num_samples)
        g = torch.Generator().manual_seed(1)
        for f in self._first_hits():
            fs = torch.full((n,), float(f), dtype=torch.float64)
            try:
                z, is_max = s.sample(fs, torch.full((n,), float(F), dtype=torch.float64), generator=g)
            except NotImplementedError:
                if self.can_sample:
                    pytest.fail(
                        f"{type(s).__name__}.sample is not implemented: Predictive and simulate_readings cannot draw "
                        "its readings; implement it, or set can_sample = False in the contract class"
                    )
                pytest.skip(f"{type(s).__name__}.sample is not implemented (can_sample = False)")
            z, is_max = torch.as_tensor(z, dtype=torch.float64), torch.as_tensor(is_max, dtype=torch.bool)
            assert z.shape == (n,) and is_max.shape == (n,), (z.shape, is_max.shape)
            hits = z[~is_max].numpy()
            if self.discrete:
                whole = np.array_equal(hits, np.round(hits)) and ((hits >= 0) & (hits <= F)).all()
                assert whole, (
                    f"first hit {f}: a discrete sensor's hits are whole cells in 0..{F}, got {hits[:4].tolist()} "
                    "(a sensor of continuous ranges: discrete = False)"
                )
                probs = [s.log_prob(torch.tensor(float(k)), f, F).exp().item() for k in range(F + 1)]
                counts = np.bincount(hits.astype(np.int64), minlength=F + 1)
            else:
                assert (hits <= F + 0.5).all(), f"first hit {f}: a hit past the ray's end is a max-range reading"
                edges = np.array([-math.inf, *np.arange(-0.5, F + 1.0, 1.0)])
                probs = [self._hit_mass(s, f, a, b) for a, b in itertools.pairwise(edges)]
                counts = np.histogram(hits, bins=edges)[0]
            p_max = math.exp(float(s.log_prob(torch.tensor(0.0), f, F, is_max=True)))
            p = torch.tensor([p_max, *probs], dtype=torch.float64)
            c = torch.tensor([int(is_max.sum()), *counts.tolist()], dtype=torch.float64)
            check_draws(p, c, f"first hit {f}: sample() against log_prob (max range, then hits by cell)")
