"""Warning and error classes shared by several layers of the library (as :mod:`numpy.exceptions` holds numpy's).

A class here imports nothing of the library, so a prior, a model, an inference routine and a guide can all
raise it without importing one another.
"""

from __future__ import annotations

__all__ = ["CheckpointError", "FittedSettingWarning"]


class FittedSettingWarning(UserWarning):
    """A fitted artefact used at a setting far from the one it was fitted for: an update term at another sensor
    setting (thesis Section 2.5), a guide at another sensor, a prior learned on plans of another cell size."""


class CheckpointError(ValueError):
    """A checkpoint that cannot be resumed here: unreadable, foreign (of another model, kernel, run or training
    setting), or holding values no run writes. The message names the file and what is wrong. Raised by
    :func:`~ogm_ppl.inference.mcmc.run_gibbs`, :func:`~ogm_ppl.learn.train_corpus_guide` and every other
    resumable workflow."""
