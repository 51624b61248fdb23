"""Learning artefacts from plan corpora, fitted on a corpus by name or on floor plans of one's own, each written with
its provenance into a folder one names: the learned priors' count tables, back-off weights, pattern fields and net
fields (:mod:`~ogm_ppl.learn.net_field`), and the update terms Delta of traditional OGM fitted against exact 1D
posteriors (the shipped setting, or one's own sensor's); the priors' tempering exponents
(:mod:`~ogm_ppl.learn.temper`) and biases (:mod:`~ogm_ppl.learn.bias`), and the headline experiment's prior
(:mod:`~ogm_ppl.learn.headline`), each scored on validation plans by the calibration protocol (``ogm-ppl
fit-prior``); the amortised guide of a corpus (:mod:`~ogm_ppl.learn.guide_training`, its windows
:mod:`~ogm_ppl.learn.guide_examples` and settings :mod:`~ogm_ppl.learn.guide_settings`; ``ogm-ppl train-guide``),
its data curve (:mod:`~ogm_ppl.learn.guide_curve`; ``ogm-ppl train-guide --curve-sizes``) and the guide of a
learned prior (:mod:`~ogm_ppl.learn.prior_guide`).

This package sits above the datasets, inference, priors and :mod:`ogm_ppl.calibration`, and below
:mod:`ogm_ppl.experiment` and the command line, which it does not import.

>>> from ogm_ppl.learn import fit_tables, fit_backoff, fit_field, fit_deltas, fit_delta_setting, train_corpus_guide
>>> from ogm_ppl.learn import fit_temper, select_headline_prior, fit_bias
>>> CORPORA
('generated', 'houseexpo', 'ipa', 'dungeon', 'houseexpo-full', 'r2v', 'schools')
"""

from ogm_ppl.learn._fit_common import CORPORA, FitOptionError, FitResult, TrainingPlans, load_training_plans
from ogm_ppl.learn.backoff import fit_backoff
from ogm_ppl.learn.bias import BiasSettings, fit_bias
from ogm_ppl.learn.delta_setting import fit_delta_setting
from ogm_ppl.learn.deltas import fit_deltas
from ogm_ppl.learn.field import FieldSettings, fit_field
from ogm_ppl.learn.guide_curve import guide_data_curve
from ogm_ppl.learn.guide_examples import TooFewWindowsError
from ogm_ppl.learn.guide_settings import GuideSettingsError, GuideTrainingSettings
from ogm_ppl.learn.guide_training import CheckpointError, GuideTrainingResult, train_corpus_guide
from ogm_ppl.learn.headline import HeadlineSettings, select_headline_prior
from ogm_ppl.learn.net_field import NetFieldSettings, fit_net_field
from ogm_ppl.learn.prior_guide import PriorGuideResult, PriorGuideSettings, train_prior_guide
from ogm_ppl.learn.tables import fit_tables
from ogm_ppl.learn.temper import TemperSettings, fit_temper

__all__ = [
    "CORPORA",
    "BiasSettings",
    "CheckpointError",
    "FieldSettings",
    "FitOptionError",
    "FitResult",
    "GuideSettingsError",
    "GuideTrainingResult",
    "GuideTrainingSettings",
    "HeadlineSettings",
    "NetFieldSettings",
    "PriorGuideResult",
    "PriorGuideSettings",
    "TemperSettings",
    "TooFewWindowsError",
    "TrainingPlans",
    "fit_backoff",
    "fit_bias",
    "fit_delta_setting",
    "fit_deltas",
    "fit_field",
    "fit_net_field",
    "fit_tables",
    "fit_temper",
    "guide_data_curve",
    "select_headline_prior",
    "train_corpus_guide",
    "train_prior_guide",
    "load_training_plans",
]
