"""Learning artefacts: the learned priors' count tables, back-off weights and pattern fields, fitted on a plan
corpus by name or on floor plans of one's own, and the update terms Delta of traditional OGM, fitted against
exact 1D posteriors (the shipped setting, or one's own sensor's); each written with its provenance into a
folder one names (``ogm-ppl fit-prior``).

>>> from ogm_ppl.learn import fit_tables, fit_backoff, fit_field, fit_deltas, fit_delta_setting
>>> sorted(CORPORA)
['dungeon', 'generated', 'houseexpo', 'ipa']
"""

from ogm_ppl.learn._fit_common import CORPORA, FitOptionError, FitResult, TrainingPlans, training_plans
from ogm_ppl.learn.backoff import fit_backoff
from ogm_ppl.learn.delta_setting import fit_delta_setting
from ogm_ppl.learn.deltas import fit_deltas
from ogm_ppl.learn.field import FieldSettings, fit_field
from ogm_ppl.learn.tables import fit_tables

__all__ = [
    "CORPORA",
    "FieldSettings",
    "FitOptionError",
    "FitResult",
    "TrainingPlans",
    "fit_backoff",
    "fit_delta_setting",
    "fit_deltas",
    "fit_field",
    "fit_tables",
    "training_plans",
]
