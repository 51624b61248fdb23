"""Map every shipped CARMEN log with the ``ogm-ppl map`` command and summarise times and sizes.

The command line of :func:`ogm_ppl.studies.map_all_logs.map_all_logs` (the logs and their options are in
:mod:`ogm_ppl.studies.map_all_logs`), on the shared data beside the repository. Writes ``out/logs/<name>/``
(the files of ``ogm-ppl map``) and ``out/logs/summary.md``.

    python experiments/map_all_logs.py [--out out/logs] [--only intel,seattle]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ogm_ppl.studies.map_all_logs import log_jobs, map_all_logs

DATA = Path(__file__).resolve().parents[2] / "shared" / "data"  # shared/ beside the repository


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=Path("out/logs"), help="output directory (default out/logs)")
    ap.add_argument("--only", help="comma-separated log names to map (default: all)")
    ap.add_argument("--data", type=Path, default=DATA, help="the shared data folder (../shared/data)")
    args = ap.parse_args(argv)
    only = args.only.split(",") if args.only else None
    for name, cli_args in log_jobs(args.data).items():
        if only is None or name in only:
            print("ogm-ppl " + " ".join(["map", *cli_args, "--out", str(args.out / name)]), flush=True)
    text, failed = map_all_logs(args.out, args.data, only)
    print(text)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
