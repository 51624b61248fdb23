"""VI against the exact posterior on the thesis's 1D toy: summed KL of marginals and wall-clock time.

The command line of :func:`ogm_ppl.studies.vi_vs_exact_1d.vi_vs_exact_1d` (the problem, the guides and the
objectives are in :mod:`ogm_ppl.studies.vi_vs_exact_1d`). Writes ``out/vi/vi_vs_exact_1d.md`` (atomically) and
prints it.

    python experiments/vi_vs_exact_1d.py [--quick]
"""

from __future__ import annotations

import argparse
from pathlib import Path

from ogm_ppl.io import atomic_write_text
from ogm_ppl.studies.errors import STUDY_ERRORS
from ogm_ppl.studies.vi_vs_exact_1d import vi_vs_exact_1d, vi_vs_exact_1d_markdown


def main(argv=None) -> str:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="a fifth of the steps (smoke test)")
    ap.add_argument("--out", default="out/vi/vi_vs_exact_1d.md", help="the Markdown file written")
    ap.add_argument("--seed", type=int, default=0, help="seed of the fits (0)")
    args = ap.parse_args(argv)
    try:
        rows = vi_vs_exact_1d(args.quick, args.seed)
    except STUDY_ERRORS as e:
        ap.error(str(e))
    text = vi_vs_exact_1d_markdown(rows, args.quick, args.seed)
    atomic_write_text(Path(args.out), text)
    print(text)
    return text


if __name__ == "__main__":
    main()
