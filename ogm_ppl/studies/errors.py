"""The refusals of the studies (:mod:`ogm_ppl.studies`): a setting out of range, an input that is not what it
should be. Each is a :class:`ValueError`, so a caller can catch a study's own refusals without catching its
bugs; :data:`STUDY_ERRORS` lists them with :class:`FileNotFoundError` (an input file or folder missing).
"""

from __future__ import annotations

__all__ = ["STUDY_ERRORS", "StudyInputError", "StudyOptionError"]


class StudyOptionError(ValueError):
    """A setting of a study out of its range; ``option`` names it as the study's settings spell it (the command
    line's spelling without the dashes: ``--gibbs-sweeps`` -> ``gibbs_sweeps``)."""

    def __init__(self, option: str, message: str) -> None:
        super().__init__(f"{option}: {message}")
        self.option = option

    @property
    def flag(self) -> str:
        """The option as a command line spells it: ``gibbs_sweeps`` -> ``--gibbs-sweeps``."""
        return "--" + self.option.replace("_", "-")


class StudyInputError(ValueError):
    """An input of a study that is not what it should be: a folder that is not an experiment's output, a file
    without the array it needs or of another size, counts that disagree with a score the experiment recorded.
    The message names the path."""


#: what a study raises for bad settings or inputs (a command line prints these as one message)
STUDY_ERRORS: tuple[type[Exception], ...] = (StudyOptionError, StudyInputError, FileNotFoundError)
