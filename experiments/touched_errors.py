"""Where maps' errors on the touched cells of an experiment lie, against the benchmark's walls.

The command line of :func:`ogm_ppl.studies.touched_errors.touched_errors` (what is counted, and how, is in
:mod:`ogm_ppl.studies.touched_errors`): for each dataset and algorithm, at the algorithm's best touched-only
threshold, the walls missed by depth and the false positives by distance to the nearest benchmark wall.

``--out DIR`` writes ``DIR/touched_errors.json`` (every count, the touched best F1 and threshold) and
``DIR/touched_errors.png`` (one panel per dataset). Results page, Intel: "Where the touched cells differ".

    python experiments/touched_errors.py out/experiments/intel_guide ogm guide-he-ipa --out out/touched
    python experiments/touched_errors.py out/experiments/intel_6_5 ogm dd-L1 --datasets intel-pf1
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from ogm_ppl.studies.errors import STUDY_ERRORS
from ogm_ppl.studies.touched_errors import touched_errors


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("folder", type=Path, help="an experiment's output folder (ogm-ppl experiment --out)")
    ap.add_argument("algorithm", nargs="+", help="the algorithms (map names) to count")
    ap.add_argument("--datasets", nargs="+", default=None, help="default: every dataset of the folder")
    ap.add_argument("--out", type=Path, default=None, help="write touched_errors.json and .png here")
    args = ap.parse_args(argv)
    try:
        result = touched_errors(args.folder, args.algorithm, datasets=args.datasets, out_dir=args.out)
    except STUDY_ERRORS as e:
        raise SystemExit(f"touched_errors.py: {e}") from None
    for d, algs in result["datasets"].items():
        for a, r in algs.items():
            print(d, a, json.dumps({k: r[k] for k in ("touched_best_f1", "false_negatives", "fp_binned")}))
    if args.out is not None:
        print(f"wrote {args.out / 'touched_errors.json'} and touched_errors.png")
    return result


if __name__ == "__main__":
    main()
