"""ogm_ppl.studies.tune_distance_offset: methods that are not per-metre methods of the spec, offsets that are not
positive and no plans are refused before anything runs; experiments/tune_distance_offset.py has its options."""

from pathlib import Path

import pytest

from ogm_ppl.studies.errors import StudyOptionError
from ogm_ppl.studies.tune_distance_offset import _key, tune_distance_offset
from tests._experiments import run_script

SPEC = Path(__file__).resolve().parents[2] / "experiments" / "specs" / "active_small.toml"


@pytest.mark.parametrize(
    "kw, match",
    [
        ({"methods": ["patch3-ig"]}, "methods: .*'patch3-ig' is not a per-metre method"),
        ({"methods": ["nothing"]}, "'nothing' is not a per-metre method"),
        ({"methods": ["indep-cov-per-m"], "offsets": [1.0, 0.0]}, "offsets: must be positive"),
        ({"methods": ["indep-cov-per-m"], "plans": 0}, "plans: must be at least 1"),
    ],
)
def test_bad_settings_are_refused(kw, match):
    with pytest.raises(StudyOptionError, match=match):
        tune_distance_offset(SPEC, progress=False, **kw)


def test_the_criterion_is_the_median_then_the_mean_reached():
    inf = float("inf")
    assert _key([1.0, 3.0, inf]) == (3.0, 2.0)
    assert _key([inf, inf]) == (inf, inf)

    def choose(runs):  # the study's rule: the smallest criterion, then the smallest offset
        return min(runs, key=lambda t: (*_key(t[1]), t[0]))[0]

    assert choose([(1.0, [2.0, 5.0]), (2.0, [3.0, 3.0])]) == 2.0  # the smaller median
    assert choose([(1.0, [2.0, 4.0]), (2.0, [3.0, 3.0])]) == 1.0  # a tie: the smaller offset


def test_the_script_has_its_options():
    r = run_script("tune_distance_offset.py", "--help")
    assert r.returncode == 0 and "--offsets" in r.stdout and "--plans" in r.stdout, r.stderr
