"""Priors and guides scored as predictors of what was not seen (thesis Chapter 5, Sections 5.2.1-5.2.3).

:mod:`~ogm_ppl.calibration.heldout` chooses the test maps (held-out corpus plans, generated maps, plan files of
other buildings); :mod:`~ogm_ppl.calibration.leakage` refuses a prior or guide on a map it was learned from.
"""

from ogm_ppl.calibration.heldout import (
    GENERATED_HELDOUT_SEED,
    PLAN_FILES_GUIDE,
    PLAN_FILES_PRIORS,
    TEST_CORPORA,
    NoUsablePlanError,
    TestMap,
    check_plan_files,
    choose_window,
    generated_windows,
    heldout_maps,
    plan_digests,
    plan_file_maps,
    usable_windows,
)
from ogm_ppl.calibration.leakage import (
    GuideNameError,
    LeakageError,
    check_heldout,
    guide_for,
    load_corpus_guide,
    names_digest,
    training_set,
)

__all__ = [
    "GENERATED_HELDOUT_SEED",
    "PLAN_FILES_GUIDE",
    "PLAN_FILES_PRIORS",
    "TEST_CORPORA",
    "GuideNameError",
    "LeakageError",
    "NoUsablePlanError",
    "TestMap",
    "check_heldout",
    "check_plan_files",
    "choose_window",
    "generated_windows",
    "guide_for",
    "heldout_maps",
    "load_corpus_guide",
    "names_digest",
    "plan_digests",
    "plan_file_maps",
    "training_set",
    "usable_windows",
]
