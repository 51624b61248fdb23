"""How far the thesis's border update (Section 5.2.3) is from the posterior it is meant to sample.

    python experiments/thesis_border_update.py      # -> out/thesis_border_update.json (a few seconds after compiling)

The command line of :func:`ogm_ppl.studies.thesis_border_update.thesis_border_update` (the problems, the exact
one-sweep matrices and the gaps are in :mod:`ogm_ppl.studies.thesis_border_update`).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from ogm_ppl.studies.thesis_border_update import (  # noqa: E402
    FILE_NAME,
    thesis_border_update,
    thesis_border_update_lines,
)


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=ROOT / "out", help="the folder of thesis_border_update.json (out)")
    args = ap.parse_args(argv)
    doc = thesis_border_update(out_dir=args.out)
    print("\n".join(thesis_border_update_lines(doc)))
    print(f"-> {args.out / FILE_NAME}")
    return doc


if __name__ == "__main__":
    main()
