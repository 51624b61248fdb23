"""Priors judged as predictors of what was not seen, on one corpus (thesis Chapter 5): the held-out protocol of
``ogm-ppl calibrate`` (:func:`ogm_ppl.calibration.calibrate`) with its test and training corpus both ``--corpus``.

Kept for the command line it had; the experiment, its scores (NLL, ECE and reliability, Brier, ROC AUC, best F1,
IoU on the near-mapped mask and its unseen cells), the chains from three starts and the leakage check are all
the calibration run's, whose other options pass through. Writes ``out/heldout/`` unless ``--out`` says otherwise.

    python experiments/heldout_priors.py --corpus houseexpo --plans 2
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from ogm_ppl.calibration import TEST_CORPORA, USER_ERRORS, CalibrationResult, SettingsError, calibrate
from ogm_ppl.cli.calibrate import build_parser, settings_from_args


def main(argv=None) -> CalibrationResult:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--corpus", default="houseexpo", choices=TEST_CORPORA, help="the test and training corpus")
    ap.add_argument("--out", default="out/heldout", help="output folder (out/heldout)")
    args, rest = ap.parse_known_args(argv)
    cal = build_parser(prog="heldout_priors.py")
    cal_args = cal.parse_args(["--test", args.corpus, "--train", args.corpus, "--out", args.out, *rest])
    try:
        return calibrate(settings_from_args(cal_args), cal_args.out)
    except SettingsError as e:
        cal.error(f"{e.flag}: {e.reason}")
    except USER_ERRORS as e:
        raise SystemExit(f"heldout_priors.py: {e}") from None


if __name__ == "__main__":
    main()
