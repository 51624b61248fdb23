"""Why the border prior trails on simulated office maps (README, Table 6.4): prior mass and likelihood of a
3 x 3 patch Gibbs chain with ``border:generated`` from the thresholded OGM start, sweep by sweep, beside the
true map's; and the true map's tiles whose (border, inner) pair the tables never counted.

The command line of :func:`ogm_ppl.studies.border_chain_probe.border_chain_probe`.

    python experiments/border_chain_probe.py out/experiments/table_6_4_small sim-m1000 [--sweeps 12]
"""

from __future__ import annotations

import argparse
from pathlib import Path

from ogm_ppl.studies.border_chain_probe import border_chain_probe, border_chain_probe_lines
from ogm_ppl.studies.errors import STUDY_ERRORS


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("folder", type=Path, help="an experiment's output folder (ogm-ppl experiment --out)")
    ap.add_argument("dataset", help="a dataset of the experiment")
    ap.add_argument("--sweeps", type=int, default=12, help="sweeps of the chain (12)")
    ap.add_argument("--sigma", type=float, default=3.0, help="range noise, cells (3)")
    args = ap.parse_args(argv)
    try:
        doc = border_chain_probe(args.folder, args.dataset, args.sweeps, args.sigma)
    except STUDY_ERRORS as e:
        ap.error(str(e))
    print("\n".join(border_chain_probe_lines(doc)))
    return doc


if __name__ == "__main__":
    main()
