"""Learning artefacts from corpora of maps: the corpus guide (:mod:`~ogm_ppl.learn.guide_training`, its windows
:mod:`~ogm_ppl.learn.guide_examples` and settings :mod:`~ogm_ppl.learn.guide_settings`; ``ogm-ppl train-guide``)
and the guide of a learned prior (:mod:`~ogm_ppl.learn.prior_guide`).

This package sits above the datasets, inference, priors and :mod:`ogm_ppl.calibration`, and below
:mod:`ogm_ppl.experiment` and the command line, which it does not import.
"""

from ogm_ppl.learn.guide_examples import TooFewWindowsError
from ogm_ppl.learn.guide_settings import GuideSettingsError, GuideTrainingSettings
from ogm_ppl.learn.guide_training import CheckpointError, GuideTrainingResult, train_corpus_guide
from ogm_ppl.learn.prior_guide import PriorGuideResult, PriorGuideSettings, train_prior_guide

__all__ = [
    "CheckpointError",
    "GuideSettingsError",
    "GuideTrainingResult",
    "GuideTrainingSettings",
    "PriorGuideResult",
    "PriorGuideSettings",
    "TooFewWindowsError",
    "train_corpus_guide",
    "train_prior_guide",
]
