"""Where the pooled errors of a Table 6.4 run lie: observed or never-observed cells, and the best F1 any map
can reach without predicting never-observed free space.

The command line of :func:`ogm_ppl.studies.table_6_4_errors.error_split` (the split and the two oracle maps
are in :mod:`ogm_ppl.studies.table_6_4_errors`): prints the summary, and with ``--json`` writes the result.

    python experiments/table_6_4_errors.py out/experiments/table_6_4_full --json out/table_6_4_errors.json
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from ogm_ppl.io import atomic_write_text
from ogm_ppl.studies.errors import STUDY_ERRORS
from ogm_ppl.studies.table_6_4_errors import error_split, error_split_text


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out_dir", type=Path, help="an experiment's output folder (holding maps/ and datasets/)")
    ap.add_argument("--algorithms", nargs="+", help="only these (default: every map of the first dataset)")
    ap.add_argument("--json", type=Path, help="also write the result to this JSON file")
    a = ap.parse_args(argv)
    try:
        res = error_split(a.out_dir, algorithms=a.algorithms)
    except STUDY_ERRORS as e:
        raise SystemExit(f"table_6_4_errors.py: {e}") from None
    print(error_split_text(res))
    if a.json:
        print("wrote", atomic_write_text(a.json, json.dumps(res, indent=1)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
