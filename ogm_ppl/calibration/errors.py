"""The errors of the calibration workflow (:func:`~ogm_ppl.calibration.run.calibrate`).

Each is a :class:`CalibrationError` and a :class:`ValueError` (a bad value given, a file that is not what it
should be), so a caller can catch the workflow's own refusals without catching its bugs. The held-out maps and
the leakage checks raise their own :class:`~ogm_ppl.calibration.leakage.LeakageError`,
:class:`~ogm_ppl.calibration.leakage.GuideNameError`, :class:`~ogm_ppl.calibration.heldout.NoUsablePlanError`
and :class:`~ogm_ppl.datasets.plan_files.PlanFileError`; :data:`USER_ERRORS` lists them all.
"""

from __future__ import annotations

from collections.abc import Sequence

from ogm_ppl.calibration.heldout import NoUsablePlanError
from ogm_ppl.calibration.leakage import GuideNameError, LeakageError
from ogm_ppl.datasets.plan_files import PlanFileError

__all__ = [
    "USER_ERRORS",
    "BiasFileError",
    "CalibrationError",
    "PriorNameError",
    "ResultFileError",
    "SettingsError",
    "SettingsMismatchError",
]


class CalibrationError(ValueError):
    """A refusal of the calibration workflow: a bad setting or input file; the message says which."""


class SettingsError(CalibrationError):
    """A setting out of its range, or settings that do not go together. ``option`` is the name of the
    :class:`~ogm_ppl.calibration.settings.CalibrationSettings` field (``"sweeps"``, ``"beta_min"``; ``"out"``
    for the output folder); the message is ``"<option>: <reason>"``, and ``flag`` the command line's
    spelling of the option (``--beta-min``)."""

    def __init__(self, option: str, reason: str):
        self.option, self.reason = option, reason
        super().__init__(f"{option}: {reason}")

    @property
    def flag(self) -> str:
        """The option as ``ogm-ppl calibrate`` spells it: ``beta_min`` -> ``--beta-min``."""
        return "--" + self.option.replace("_", "-")


class PriorNameError(CalibrationError):
    """A prior named in the settings that cannot be built: an unknown kind, a corpus without tables, tables
    that cannot be read. Raised before any work starts."""


class BiasFileError(CalibrationError):
    """A bias file (``bias_file``) that is unreadable or not of format
    :data:`~ogm_ppl.calibration.names.BIAS_FORMAT` with finite biases; the message names the file."""


class ResultFileError(CalibrationError):
    """An existing ``calibration.json`` in the output folder that is not a calibration result (rerun with
    ``fresh=True``); the message names the file."""


class SettingsMismatchError(ResultFileError):
    """An existing ``calibration.json`` whose run settings (:data:`~ogm_ppl.calibration.results.RUN_KEYS`)
    differ from this run's: a resumed run must share them. ``keys`` lists those that differ."""

    def __init__(self, path: str, keys: Sequence[str]):
        self.keys = list(keys)
        super().__init__(
            f"{path}: its settings differ in {self.keys}; rerun fresh (--fresh) or into another folder (--out)"
        )


#: every exception the workflow raises for bad settings or input files (the command line prints these as one
#: message and exits with status 2)
USER_ERRORS: tuple[type[Exception], ...] = (
    CalibrationError,
    LeakageError,
    GuideNameError,
    NoUsablePlanError,
    PlanFileError,
)
