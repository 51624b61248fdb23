"""Variational inference: Pyro guides over maps (mean field, patches, first hit), their objectives, and the
fit of inverse sensor models Delta as amortised VI (Section 2.5)."""

from ogm_ppl.inference.variational.delta_fit import (
    FitResult,
    cross_entropy_loss,
    cross_validate,
    fit_delta,
)
from ogm_ppl.inference.variational.guides import MeanFieldGuide, PatchGuide, fit_guide
from ogm_ppl.inference.variational.structured_guides import ExactELBO, FirstHitGuide

__all__ = [
    "MeanFieldGuide", "PatchGuide", "FirstHitGuide", "ExactELBO", "fit_guide",
    "fit_delta", "cross_entropy_loss", "cross_validate", "FitResult",
]  # fmt: skip

# amortised inference compiled from the model (inference compilation; issue #12 item 3)
from ogm_ppl.inference.variational.amortised import (
    AmortisedGuide,
    GuideFileError,
    evidence_features,
    guide_initial_map,
    random_scene,
    shipped_guide,
)

# update terms fitted for a sensor setting, and the warning for a term used outside its own (issue #11 item 4)
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

__all__ += ["AmortisedGuide", "GuideFileError", "evidence_features", "guide_initial_map", "random_scene",
            "shipped_guide"]  # fmt: skip
__all__ += ["fit_delta_for_setting", "fit_deltas_for_setting", "fit_family_for", "fit_on_data", "check_delta_setting", "FittedSettingWarning",
            "save_setting_fit", "load_setting_fit", "setting_file_name", "SIGMA_TOLERANCE", "F_FACTOR"]  # fmt: skip
