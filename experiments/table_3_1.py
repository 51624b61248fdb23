"""Table 3.1: average summed KL between each mapping algorithm and the exact posterior, 1000 1D datasets.

The command line of :func:`ogm_ppl.studies.table_3_1.table_3_1` (the datasets, the rows and the score are in
:mod:`ogm_ppl.studies.table_3_1`).

    python experiments/table_3_1.py [--datasets 1000] [--gibbs-sweeps 100000] [--cells 30] [--seed 0]

Writes out/experiments/table_3_1.{md,json} (or into --out) and prints the table.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from ogm_ppl.studies.errors import STUDY_ERRORS
from ogm_ppl.studies.table_3_1 import Table31Settings, table_3_1, table_3_1_markdown

OUT = Path(__file__).resolve().parent.parent / "out" / "experiments"


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--datasets", type=int, default=1000, help="random 1D datasets (1000)")
    ap.add_argument("--gibbs-sweeps", type=int, default=100_000, help="Gibbs sweeps per dataset, 0: no Gibbs row")
    ap.add_argument("--cells", type=int, default=30, help="latent cells K (30)")
    ap.add_argument("--seed", type=int, default=0, help="seed of the datasets and chains (0)")
    ap.add_argument("--out", type=Path, default=OUT, help="the folder of table_3_1.md and .json (out/experiments)")
    args = ap.parse_args(argv)
    settings = Table31Settings(args.datasets, args.gibbs_sweeps, args.cells, args.seed)
    try:
        res = table_3_1(settings, args.out)
    except STUDY_ERRORS as e:
        ap.error(str(e))
    print(table_3_1_markdown(res))
    return res


if __name__ == "__main__":
    main()
