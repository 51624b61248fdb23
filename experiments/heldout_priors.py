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

sys.path.insert(0, str(Path(__file__).resolve().parent))

import calibration  # experiments/calibration.py, the script form of ogm-ppl calibrate

from ogm_ppl.calibration import TEST_CORPORA, CalibrationResult


def main(argv=None) -> CalibrationResult:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--corpus", default="houseexpo", choices=TEST_CORPORA)
    ap.add_argument("--out", default="out/heldout")
    args, rest = ap.parse_known_args(argv)
    return calibration.main(["--test", args.corpus, "--train", args.corpus, "--out", args.out, *rest])


if __name__ == "__main__":
    main()
