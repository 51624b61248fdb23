"""Fit every update term of Table 2.1, pN for N = 1..21 and a neural inverse sensor model against exact 1D
posteriors, with 10-fold cross-validation (Section 2.5): :func:`ogm_ppl.learn.fit_deltas`
(``ogm-ppl fit-prior deltas``), which documents the data, the objective and the files.

    python experiments/fit_deltas.py [--write-artefacts] [--folds 10] [--datasets 1000]

Writes the report out/experiments/delta_cv.{md,json} and the fitted terms into out/experiments/deltas/; with
--write-artefacts into ogm_ppl/fitted/ instead (delta_<name>.json and delta_cv.json, the shipped terms).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from ogm_ppl.io import atomic_write_text
from ogm_ppl.learn import fit_deltas

ROOT = Path(__file__).resolve().parent.parent


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--folds", type=int, default=10)
    ap.add_argument("--datasets", type=int, default=1000)
    ap.add_argument("--write-artefacts", action="store_true")
    args = ap.parse_args()
    report = ROOT / "out" / "experiments"
    out = ROOT / "ogm_ppl" / "fitted" if args.write_artefacts else report / "deltas"
    r = fit_deltas(out, datasets=args.datasets, folds=args.folds)
    summary = {k: v for k, v in r.summary.items() if k != "markdown"}
    atomic_write_text(report / "delta_cv.md", r.summary["markdown"])
    atomic_write_text(report / "delta_cv.json", json.dumps(summary, indent=2))
    print(r.summary["markdown"])


if __name__ == "__main__":
    main()
