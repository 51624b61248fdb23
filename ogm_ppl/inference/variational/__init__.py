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

__all__ += ["AmortisedGuide", "GuideFileError", "evidence_features", "guide_initial_map", "random_scene",
            "shipped_guide"]  # fmt: skip
