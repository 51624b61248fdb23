"""ogm_ppl.calibration.settings: the defaults that depend on other settings, and every bad value refused with a
SettingsError that names the option."""

import pytest

from ogm_ppl.calibration import (
    DEFAULT_TEST_CORPORA,
    PLAN_FILES_GUIDE,
    PLAN_FILES_PRIORS,
    TEST_CORPORA,
    CalibrationError,
    CalibrationSettings,
    SettingsError,
)
from ogm_ppl.calibration.settings import parse_patch_overrides


def test_defaults_follow_the_plan_files():
    assert CalibrationSettings(plan_files=("x",)).resolved().test == ()
    assert CalibrationSettings().resolved().test == DEFAULT_TEST_CORPORA  # the thesis's; the others by name
    assert set(DEFAULT_TEST_CORPORA) < set(TEST_CORPORA)
    s = CalibrationSettings(plan_files=("x",))  # no plans: 2 maps a corpus, every plan of the plan set
    assert (s.maps_per_corpus, s.plans) == (2, None)
    r = s.resolved()
    assert r.guides == (PLAN_FILES_GUIDE,) and CalibrationSettings().resolved().guides == ()  # the floor-plan guide
    assert r.priors == PLAN_FILES_PRIORS  # and a few priors, not every kind
    assert len(CalibrationSettings(plan_files=("x",), test=("ipa",)).resolved().priors) > len(PLAN_FILES_PRIORS)
    assert CalibrationSettings(plan_files=("x",), guides=()).resolved().guides == ()
    assert CalibrationSettings(plan_files=("x",), plans=3).plans == 3


def test_quick_sets_the_smoke_run_sizes_over_those_given():
    r = CalibrationSettings(quick=True, window=96, priors=("patch3",)).resolved()
    assert (r.plans, r.window, r.sweeps, r.burn, r.generated_shape) == (1, 48, 40, 10, 96)
    assert r.priors == ("patch3",) and r.train == ("houseexpo",)
    assert CalibrationSettings(quick=True).resolved().priors == ("independent", "mrf", "border")


def test_patch_overrides():
    assert parse_patch_overrides(["border1=3x3", "patch3=1"]) == {"border1": (3, 3), "patch3": None}
    for bad in ("border1=3", "border1=ax3", "border1=0x3"):
        with pytest.raises(SettingsError, match="patch: takes KIND=RxC"):
            parse_patch_overrides([bad])


@pytest.mark.parametrize(
    "over, option",
    [
        ({"sweeps": 3}, "sweeps"),
        ({"burn": -1}, "burn"),
        ({"plans": 0}, "plans"),
        ({"window": 0}, "window"),
        ({"beams": 0}, "beams"),
        ({"sigma": 0.0}, "sigma"),
        ({"range_cells": float("nan")}, "range_cells"),
        ({"seed": -1}, "seed"),
        ({"max_support": 0}, "max_support"),
        ({"test": ("nowhere",)}, "test"),
        ({"kernel": "metropolis"}, "kernel"),
        ({"temper": "all"}, "temper"),
        ({"kernel": "tempering", "beta_min": 1.5}, "beta_min"),
        ({"kernel": "tempering", "rungs": 0}, "rungs"),
        ({"patch": ("border1=3",)}, "patch"),
        ({"plan_files": ("x",), "plan_set": "generated"}, "plan_set"),  # a corpus's name
        ({"plan_files": ("x",), "plan_set": "IPA"}, "plan_set"),
        ({"plan_files": ("x",), "plan_set": "none"}, "plan_set"),
        ({"plan_files": ("x",), "plan_set": "a b"}, "plan_set"),
        ({"plan_files": ("x",), "pixel_size": -0.05}, "pixel_size"),
        ({"pixel_size": 0.05}, "pixel_size"),  # without plan files
        ({"plan_outside": "unknown"}, "plan_outside"),  # without plan files
        ({"plan_outside": "walls", "plan_files": ("x",)}, "plan_outside"),
    ],
)
def test_a_bad_value_names_its_option(over, option):
    with pytest.raises(SettingsError, match=f"^{option}: ") as e:
        CalibrationSettings(**over)
    assert e.value.option == option and e.value.flag == "--" + option.replace("_", "-")
    assert isinstance(e.value, CalibrationError) and isinstance(e.value, ValueError)


def test_tempering_settings_are_checked_with_the_tempering_kernel_only():
    CalibrationSettings(beta_min=1.5, rungs=0)  # gibbs: they are not used
