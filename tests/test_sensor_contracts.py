"""Every shipped sensor passes :class:`~ogm_ppl.testing.SensorContract`, and the contract fails sensors with
the bugs a user's trial found it blind to (a sampler that drops a component, vectorisation that reads one
element's flags, a continuous sensor that does not say so, a hit past the last cell read as none)."""

import pytest
import torch

from ogm_ppl import GaussianRange, PatternMatch
from ogm_ppl.sensors_compiled import PatternReading
from ogm_ppl.testing import SensorContract


class TestGaussian(SensorContract):
    def make_sensor(self):
        return GaussianRange(2.0)


class TestGaussianWithRandomReadings(SensorContract):
    def make_sensor(self):
        return GaussianRange(1.5, p_rand=0.1)


class TestPatternMatch(SensorContract):
    discrete = True

    def make_sensor(self):
        return PatternMatch(0.8)


class _DropsRandomInSample(GaussianRange):
    def sample(self, f, F, generator=None):
        return GaussianRange(self.sigma).sample(f, F, generator=generator)


class _FirstFlagOnly(GaussianRange):
    def log_prob(self, z, f, F, is_max=None):
        if is_max is not None:
            is_max = (
                torch.as_tensor(is_max)
                .flatten()[0]
                .expand(torch.broadcast_shapes(torch.as_tensor(z).shape, torch.as_tensor(f).shape))
            )
        return super().log_prob(z, f, F, is_max)


class _Undeclared(GaussianRange):
    continuous_range = False


class _PastLastCellIsNone(GaussianRange):
    def log_prob(self, z, f, F, is_max=None):
        f = torch.as_tensor(f, dtype=torch.float64)
        F_ = torch.as_tensor(F, dtype=torch.float64)
        return super().log_prob(z, torch.where(f > F_, F_ + 1.0, f), F, is_max)


class _RandomDensityOfOneRayLength(GaussianRange):
    """Random hits on a ray with nothing in it of density ``p_rand / 13`` whatever its length (right for rays of
    12 cells only, the contract's ``F``)."""

    def log_prob(self, z, f, F, is_max=None):
        out = super().log_prob(z, f, F, is_max)
        F = torch.as_tensor(F, dtype=torch.float64)
        none = torch.as_tensor(f, dtype=torch.float64) > F + 0.5
        shift = torch.where(none, torch.log((F + 1.0) / 13.0), torch.zeros_like(F))
        if is_max is not None:
            shift = torch.where(torch.as_tensor(is_max, dtype=torch.bool), 0.0, shift)
        return out + shift


class _CompiledDropsRandom(GaussianRange):
    """A compiled face without the share of random readings its ``log_prob`` has."""

    def compiled(self, bin_width=None):
        return super().compiled(bin_width)._replace(p_rand=0.0)


class _CompiledOtherMatch(PatternMatch):
    """A compiled face whose matching outcome is a little less likely than ``log_prob``'s."""

    def compiled(self, bin_width=None):
        return PatternReading(p_occ=self.p_occ - 0.01)


class _CannotSample(GaussianRange):
    def sample(self, f, F, generator=None):
        raise NotImplementedError


@pytest.mark.parametrize(
    "sensor, check",
    [
        (_DropsRandomInSample(1.5, p_rand=0.1), "test_samples_follow_log_prob"),
        (_FirstFlagOnly(1.5, p_rand=0.1), "test_log_prob_is_vectorised"),
        (_Undeclared(1.5), "test_declares_its_kind_of_range"),
        (_PastLastCellIsNone(1.5, p_rand=0.1), "test_samples_follow_log_prob"),
        (_RandomDensityOfOneRayLength(1.5, p_rand=0.1), "test_log_prob_normalises"),
        (_CannotSample(1.5), "test_samples_follow_log_prob"),
        (_CompiledDropsRandom(1.5, p_rand=0.01), "test_compiled_reading_model_matches_log_prob"),
        (_CompiledOtherMatch(0.8), "test_compiled_reading_model_matches_log_prob"),
    ],
    ids=[
        "sample-drops-a-component",
        "vectorised-reads-one-flag",
        "continuous-undeclared",
        "past-last-cell-none",
        "normalised-on-one-ray-length",
        "cannot-sample-undeclared",
        "compiled-drops-random-readings",
        "compiled-other-constant",
    ],
)
def test_the_contract_fails_a_buggy_sensor(sensor, check):
    class Contract(SensorContract):
        discrete = isinstance(sensor, PatternMatch)

        def make_sensor(self):
            return sensor

    with pytest.raises((AssertionError, pytest.fail.Exception)):
        getattr(Contract(), check)()


def test_a_sensor_that_cannot_sample_says_so():
    class Contract(SensorContract):
        can_sample = False

        def make_sensor(self):
            return _CannotSample(1.5)

    with pytest.raises(pytest.skip.Exception):
        Contract().test_samples_follow_log_prob()
    Contract().test_log_prob_normalises()
