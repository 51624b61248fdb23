"""Variational inference: Pyro guides over maps (mean field, patches, first hit) and their objectives,
the amortised guide compiled from the model (inference compilation), and the fit of inverse sensor
models Delta as amortised VI (Section 2.5), for a sensor setting too, with the warning for a fitted term
used outside the setting it was fitted for."""

from ogm_ppl.inference.variational.amortised import (
    AmortisedGuide,
    GuideFileError,
    corpus_guide,
    corpus_guides,
    evidence_features,
    guide_initial_map,
    random_scene,
    shipped_guide,
)
from ogm_ppl.inference.variational.delta_fit import (
    DeltaFitResult,
    cross_entropy_loss,
    cross_validate,
    fit_delta,
)
from ogm_ppl.inference.variational.elbo import ExactELBO
from ogm_ppl.inference.variational.guides import MeanFieldGuide, PatchGuide, fit_guide
from ogm_ppl.inference.variational.setting_fit import (
    F_FACTOR,
    SIGMA_TOLERANCE,
    FittedSettingWarning,
    check_delta_setting,
    fit_delta_for_setting,
    fit_deltas_for_setting,
    fit_family_for,
    fit_on_data,
    load_setting_fit,
    save_setting_fit,
    setting_file_name,
)
from ogm_ppl.inference.variational.structured_guides import FirstHitGuide

__all__ = [
    "F_FACTOR",
    "SIGMA_TOLERANCE",
    "AmortisedGuide",
    "ExactELBO",
    "FirstHitGuide",
    "DeltaFitResult",
    "FittedSettingWarning",
    "GuideFileError",
    "MeanFieldGuide",
    "PatchGuide",
    "check_delta_setting",
    "corpus_guide",
    "corpus_guides",
    "cross_entropy_loss",
    "cross_validate",
    "evidence_features",
    "fit_delta",
    "fit_delta_for_setting",
    "fit_deltas_for_setting",
    "fit_family_for",
    "fit_guide",
    "fit_on_data",
    "guide_initial_map",
    "load_setting_fit",
    "random_scene",
    "save_setting_fit",
    "setting_file_name",
    "shipped_guide",
]
