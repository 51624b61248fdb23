"""Priors and guides scored as predictors of what was not seen (thesis Chapter 5, Sections 5.2.1-5.2.3).

:func:`~ogm_ppl.calibration.run.calibrate` runs the protocol (``ogm-ppl calibrate`` on the command line) with
the options of :class:`~ogm_ppl.calibration.settings.CalibrationSettings`. Its parts:
:mod:`~ogm_ppl.calibration.heldout` chooses the test maps (held-out corpus plans, generated maps, plan files of
other buildings); :mod:`~ogm_ppl.calibration.leakage` refuses a prior or guide on a map it was learned from;
:mod:`~ogm_ppl.calibration.scenes` scans a test map sparsely and scores marginals on its unseen and near-mapped
cells; :mod:`~ogm_ppl.calibration.chains` runs a prior's chains (and the OGM baseline, a corpus guide);
:mod:`~ogm_ppl.calibration.names` names the methods and digests what each scores;
:mod:`~ogm_ppl.calibration.results` keeps the rows and resumes a run; :mod:`~ogm_ppl.calibration.report`
writes the tables and figures; :mod:`~ogm_ppl.calibration.errors` holds the refusals.
"""

from ogm_ppl.calibration.chains import (
    KERNELS,
    RHAT_THRESHOLD,
    STARTS,
    agreeing,
    default_patch,
    run_guide,
    run_ogm,
    run_prior,
    run_prior_chains,
    support,
)
from ogm_ppl.calibration.errors import (
    USER_ERRORS,
    BiasFileError,
    CalibrationError,
    PriorNameError,
    ResultFileError,
    SettingsError,
    SettingsMismatchError,
)
from ogm_ppl.calibration.heldout import (
    DEFAULT_TEST_CORPORA,
    GENERATED_HELDOUT_SEED,
    PLAN_FILES_GUIDE,
    PLAN_FILES_PRIORS,
    TEST_CORPORA,
    NoUsablePlanError,
    TestMap,
    check_plan_files,
    choose_window,
    generated_seed,
    generated_windows,
    heldout_maps,
    plan_digests,
    plan_file_maps,
    usable_windows,
)
from ogm_ppl.calibration.leakage import (
    GUIDE_JOIN,
    GUIDE_PREFIX,
    GUIDE_SYM,
    GuideNameError,
    LeakageError,
    check_heldout,
    guide_corpora,
    guide_for,
    guide_path,
    guide_plans,
    guide_training_sets,
    load_corpus_guide,
    names_digest,
    training_set,
)
from ogm_ppl.calibration.names import (
    BIAS_FORMAT,
    BIAS_SUFFIX,
    OGM_LABEL,
    OWN,
    default_priors,
    load_bias_file,
    name_digest,
    prior_names,
)
from ogm_ppl.calibration.results import METRICS, RUN_KEYS, drop_changed, summary
from ogm_ppl.calibration.run import CalibrationResult, calibrate
from ogm_ppl.calibration.scenes import MASKS, CalibrationScene, make_scene, plan_set_maps, score_marginals
from ogm_ppl.calibration.settings import CalibrationSettings

__all__ = [
    "BIAS_FORMAT",
    "BIAS_SUFFIX",
    "GENERATED_HELDOUT_SEED",
    "GUIDE_JOIN",
    "GUIDE_PREFIX",
    "GUIDE_SYM",
    "KERNELS",
    "MASKS",
    "METRICS",
    "OGM_LABEL",
    "OWN",
    "PLAN_FILES_GUIDE",
    "PLAN_FILES_PRIORS",
    "RHAT_THRESHOLD",
    "RUN_KEYS",
    "STARTS",
    "DEFAULT_TEST_CORPORA",
    "TEST_CORPORA",
    "USER_ERRORS",
    "BiasFileError",
    "CalibrationError",
    "CalibrationResult",
    "CalibrationSettings",
    "GuideNameError",
    "LeakageError",
    "NoUsablePlanError",
    "PriorNameError",
    "ResultFileError",
    "CalibrationScene",
    "SettingsError",
    "SettingsMismatchError",
    "TestMap",
    "agreeing",
    "calibrate",
    "check_heldout",
    "check_plan_files",
    "choose_window",
    "default_patch",
    "default_priors",
    "drop_changed",
    "generated_seed",
    "generated_windows",
    "guide_corpora",
    "guide_plans",
    "guide_training_sets",
    "guide_for",
    "guide_path",
    "heldout_maps",
    "load_bias_file",
    "load_corpus_guide",
    "make_scene",
    "name_digest",
    "names_digest",
    "plan_digests",
    "plan_file_maps",
    "plan_set_maps",
    "prior_names",
    "run_prior_chains",
    "run_guide",
    "run_ogm",
    "run_prior",
    "score_marginals",
    "summary",
    "support",
    "training_set",
    "usable_windows",
]
