"""Mean marginal of the never-observed cells of each map an experiment wrote, per algorithm and dataset.

The command line of :func:`ogm_ppl.studies.unobserved_marginals.unobserved_means` (the cells and the mean are
in :mod:`ogm_ppl.studies.unobserved_marginals`): prints one line per algorithm, or the JSON with ``--json``.

    python experiments/unobserved_marginals.py out/experiments/table_6_4_tempered
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from ogm_ppl.studies.errors import STUDY_ERRORS
from ogm_ppl.studies.unobserved_marginals import unobserved_means, unobserved_text


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out_dir", type=Path, help="an experiment's output folder (holding maps/)")
    ap.add_argument("--baseline", default="ogm", help="the traditional-OGM algorithm of the spec")
    ap.add_argument("--json", action="store_true", help="print JSON instead of a table")
    a = ap.parse_args(argv)
    try:
        res = unobserved_means(a.out_dir, a.baseline)
    except STUDY_ERRORS as e:
        raise SystemExit(f"unobserved_marginals.py: {e}") from None
    print(json.dumps(res, indent=1) if a.json else unobserved_text(res))
    return 0


if __name__ == "__main__":
    sys.exit(main())
