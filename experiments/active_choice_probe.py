r"""What the information-gain rule trades away: at every stop of a ``sample_info`` run, the candidates' information
gain beside their expected newly observed cells, both over the same posterior samples.

    python experiments/active_choice_probe.py out/active_medium --method patch3-ig --seed 0

The command line of :func:`ogm_ppl.studies.active_choice_probe.active_choice_probe` (the scores and the pooled
summary are in :mod:`ogm_ppl.studies.active_choice_probe`): prints, per plan, the stops probed and whether the
rerun matches the task, then the summary, and writes ``OUT/choice_probe_METHOD.json``.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from ogm_ppl.studies.active_choice_probe import active_choice_probe
from ogm_ppl.studies.errors import STUDY_ERRORS


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("out", type=Path, help="the --out directory of an active experiment")
    ap.add_argument("--method", default="patch3-ig", help="a sample_info method of the run's spec")
    ap.add_argument("--seed", type=int, default=0, help="the spec seed (default 0)")
    args = ap.parse_args(argv)
    try:
        res = active_choice_probe(args.out, args.method, args.seed)
    except STUDY_ERRORS as e:
        raise SystemExit(f"active_choice_probe.py: {e}") from None
    for pid, same in res["reruns"].items():
        n = sum(r["plan"] == pid for r in res["stops"])
        print(f"{pid}: {n} stops probed; rerun matches the task's path to 90 % coverage: {same}")
    print(json.dumps(res["summary"], indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
