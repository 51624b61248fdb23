from ogm_ppl import GaussianRange, PatternMatch
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
