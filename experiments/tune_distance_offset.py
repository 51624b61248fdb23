r"""Choose the distance offset ``d_0`` of the per-metre exploration rules on *validation* plans, never on the
held-out plans the ``active`` experiments score.

    python experiments/tune_distance_offset.py experiments/specs/active_medium.toml \
        --methods patch3-cov-per-m indep-cov-per-m --offsets 0.5 1 2 4 --plans 8 --out out/tune_d0.json

The command line of :func:`ogm_ppl.studies.tune_distance_offset.tune_distance_offset` (the protocol and the
criterion are in :mod:`ogm_ppl.studies.tune_distance_offset`). Writes ``--out`` (JSON): every run's path to 90 %
coverage and to F1 0.9, the per-offset summary and the chosen offset per method, with the validation plans used.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from ogm_ppl.io import atomic_write_text
from ogm_ppl.studies.errors import STUDY_ERRORS
from ogm_ppl.studies.tune_distance_offset import tune_distance_offset


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("spec", type=Path, help="an active spec (robot, stops, corpus, window and the methods)")
    ap.add_argument("--methods", nargs="+", required=True, help="per-metre methods of the spec to tune")
    ap.add_argument("--offsets", nargs="+", type=float, default=[0.5, 1.0, 2.0, 4.0], help="d_0 values (m)")
    ap.add_argument("--plans", type=int, default=8, help="validation plans (default 8)")
    ap.add_argument("--out", type=Path, default=Path("out/tune_distance_offset.json"), help="the JSON written")
    args = ap.parse_args(argv)
    try:
        doc = tune_distance_offset(args.spec, args.methods, args.offsets, args.plans)
    except STUDY_ERRORS as e:
        raise SystemExit(f"tune_distance_offset.py: {e}") from None
    for name, d0 in doc["chosen"].items():
        print(f"{name}: chosen d0 = {d0:g} m")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_text(args.out, json.dumps(doc, indent=1, allow_nan=True))
    print(args.out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
