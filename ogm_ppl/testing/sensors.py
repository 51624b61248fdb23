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
  draw (``sample`` raises ``NotImplementedError``) fails unless its contract class sets ``can_sample = False``;
* **its compiled face agrees** (a sensor whose ``compiled()`` returns a reading bundle,
  :mod:`ogm_ppl.sensors_compiled`; skipped for one that returns ``None``): the kind is continuous exactly when
  the sensor is; on every ray length, for the first hits above, the possible readings (a discrete sensor's
  cells; ranges spread over ``[-3, F + 1/2]``) and max range, the compiled ``log_reading`` gives the sensor's
  ``log_prob`` to ``1e-12`` relative (absolute below ``|log p| = 1``; where ``log_prob`` is below ``-600`` the
  compiled value only has to be too, its tails underflowing there). Both sides evaluate one closed form in
  float64 with a few tens of roundings and special functions good to a few ulps, so they differ by ``~1e-14``
  where they agree; a wrong constant (a share ``p_rand = 0.01`` left out: ``1e-2``) is far above the
  tolerance. The outcome probabilities (``bin_prob``, range bins of each of ``bin_widths`` cells for a
  continuous sensor) sum to one and ``fill_row`` gives them (to ``1e-12``), the max-range outcome's is
  ``exp(log_prob)`` of max range, and a continuous sensor's bins hold the mass of its density (quadrature, to
  ``1e-7``);
* **its compiled draws follow** the outcome probabilities: ``num_samples`` outcomes from the kind's ``draw``
  per first hit (fixed seed), chi-square against ``bin_prob`` as above.
"""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
import torch

from ogm_ppl.testing._stats import check_draws

_UNDERFLOW = -600.0  # log-probabilities below this may underflow in one evaluation and not in another

__all__ = ["SensorContract"]


class SensorContract:
    """Mix into a pytest class and define ``make_sensor()`` (module docstring)."""

    F = 12  #: the ray length of the vectorisation and sampling checks
    ray_lengths: tuple[int, ...] = (1, 12, 100)  #: ray lengths of the normalisation check
    discrete = False  # True for sensors whose hits are whole cells (PatternMatch)
    can_sample = True  #: False: ``sample`` is not implemented (Predictive cannot draw the sensor's readings)
    num_samples = 20000  #: draws per first hit in the sampling check
    bin_widths: tuple[float, ...] = (1.0, 0.35)  #: a continuous sensor's range bins in the compiled checks

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

    def _readings(self):
        """``(sensor, [reading bundles])``: the compiled faces to check (one per bin width if continuous)."""
        s = self.make_sensor()
        face = getattr(s, "compiled", None)
        if not callable(face) or face() is None:
            pytest.skip(f"{type(s).__name__} has no compiled reading model (compiled() returns None)")
        from ogm_ppl.sensors_compiled import is_continuous

        reading = face()
        assert is_continuous(reading) == (not self.discrete), (
            f"{type(s).__name__}.compiled() returns {type(reading).__name__}, registered with continuous="
            f"{is_continuous(reading)}, but the contract's discrete = {self.discrete}"
        )
        return s, [(None, reading)] if self.discrete else [(w, face(w)) for w in self.bin_widths]

    def test_compiled_reading_model_matches_log_prob(self):
        from ogm_ppl.testing._compiled_readings import compiled_log_readings, compiled_rows

        s, readings = self._readings()
        for F in self.ray_lengths:
            if self.discrete:
                ys = np.zeros(F + 2)
                outcomes = np.arange(F + 2)
            else:
                ys = np.concatenate([np.linspace(-3.0, F + 0.5, 4 * F + 7), [0.0]])  # hits, then max range
                outcomes = np.zeros(ys.shape[0], np.int64)
            maxes = np.zeros(ys.shape[0], np.bool_)
            maxes[-1] = True
            for f in self._first_hits(F):
                none = f > (F if self.discrete else F + 0.5)
                z = torch.from_numpy(outcomes.astype(np.float64) if self.discrete else ys)
                ref = s.log_prob(z, float(f), float(F), is_max=torch.from_numpy(maxes)).double().numpy()
                fc = 0.0 if none else float(f)
                for width, reading in readings:
                    got = compiled_log_readings(reading, self.discrete, ys, outcomes, maxes, fc, none, float(F))
                    for i in range(ys.shape[0]):
                        a, b = float(got[i]), float(ref[i])
                        ok = (a == b) or abs(a - b) <= 1e-12 * max(1.0, abs(b)) or (b < _UNDERFLOW and a < _UNDERFLOW)
                        assert ok, (
                            f"{type(reading).__name__} on a ray of {F} cells, first hit {f}, reading "
                            f"{'max range' if maxes[i] else (outcomes[i] if self.discrete else ys[i])}: "
                            f"compiled log p {a}, log_prob {b}"
                        )
                    by_bin, filled = compiled_rows(reading, fc, none, float(F))
                    what = f"{type(reading).__name__} {reading} on a ray of {F} cells, first hit {f}"
                    assert abs(by_bin.sum() - 1.0) < 1e-12, f"{what}: outcome probabilities sum to {by_bin.sum()}"
                    assert np.abs(filled - by_bin).max() <= 1e-12, f"{what}: fill_row differs from bin_prob"
                    p_max = math.exp(float(s.log_prob(torch.tensor(0.0), float(f), float(F), is_max=True)))
                    assert abs(by_bin[-1] - p_max) <= 1e-12 * max(p_max, 1e-300) or p_max < 1e-250, (
                        f"{what}: max-range outcome {by_bin[-1]}, log_prob's {p_max}"
                    )
                    if not self.discrete and F == self.F:
                        self._check_bins(s, float(width), by_bin, float(f), F, what)

    def _check_bins(self, s, w: float, by_bin, f: float, F: int, what: str) -> None:
        """A continuous sensor's range bins (edges ``-1/2 + j w``, the first open below, the last ending at
        ``F + 1/2``) hold the mass of its density."""
        J = len(by_bin) - 1
        edges = [-math.inf, *(-0.5 + j * w for j in range(1, J)), F + 0.5]
        for j in range(J):
            mass = self._hit_mass(s, f, edges[j], edges[j + 1], F)
            if j == 0:
                mass = self._hit_mass(s, f, -math.inf, -0.5, F) + self._hit_mass(s, f, -0.5, edges[1], F)
            assert abs(by_bin[j] - mass) < 1e-7, f"{what}: bin {j} holds {by_bin[j]}, the density {mass}"

    def test_compiled_draws_follow_the_reading_model(self):
        from ogm_ppl.testing._compiled_readings import compiled_draws, compiled_rows

        _, readings = self._readings()
        F, n = self.F, int(self.num_samples)
        rng = np.random.default_rng(2)
        for _, reading in readings:
            for f in self._first_hits():
                none = f > (F if self.discrete else F + 0.5)
                fc = 0.0 if none else float(f)
                u_a, u_b, e = rng.random(n), rng.random(n), rng.standard_normal(n)
                jbs, _ = compiled_draws(reading, fc, none, float(F), u_a, u_b, e)
                by_bin, _ = compiled_rows(reading, fc, none, float(F))
                assert ((jbs >= 0) & (jbs < len(by_bin))).all(), f"first hit {f}: an outcome outside 0..J"
                counts = np.bincount(jbs, minlength=len(by_bin))
                check_draws(
                    torch.from_numpy(by_bin),
                    torch.from_numpy(counts.astype(np.float64)),
                    f"{type(reading).__name__} {reading}, first hit {f}: compiled draw against bin_prob",
                )
