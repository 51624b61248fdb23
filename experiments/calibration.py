"""Priors as predictors of what was not seen, and how well calibrated they are (thesis Chapter 5, 5.2.1-5.2.3):
the script form of ``ogm-ppl calibrate`` (:func:`ogm_ppl.calibration.calibrate`), with the same options.

    python experiments/calibration.py --quick        # smoke run, 1 small map per corpus, 3 priors
    python experiments/calibration.py --help         # the protocol and every option
"""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from ogm_ppl.calibration import USER_ERRORS, CalibrationResult, SettingsError, calibrate
from ogm_ppl.cli.calibrate import build_parser, settings_from_args


def main(argv: list[str] | None = None) -> CalibrationResult:
    """Parse ``argv`` as ``ogm-ppl calibrate`` does and run :func:`~ogm_ppl.calibration.calibrate`; a bad option
    or input exits with its message."""
    ap = build_parser(prog="calibration.py")
    args = ap.parse_args(argv)
    try:
        settings = settings_from_args(args)
    except SettingsError as e:
        ap.error(f"{e.flag}: {e.reason}")
    try:
        return calibrate(settings, args.out)
    except USER_ERRORS as e:
        raise SystemExit(f"calibration.py: {e}") from None


if __name__ == "__main__":
    main()
