r"""What the information-gain rule trades away: at every stop of a ``sample_info`` run, the candidates' information
gain beside their expected newly observed cells, both over the same posterior samples.

    python experiments/active_choice_probe.py out/active_medium --method patch3-ig --seed 0

Reruns the named method of an ``active`` run (its spec, plans and seeds from ``OUT``: the same runs, since a run
is a function of its seed) and, at every stop, scores the candidates the rule scored by both
``beam_information`` (summed over the beams, bits: what the rule maximises) and ``expected_new_cells`` (over
the scan's beams: what coverage counts). Prints and writes (``OUT/choice_probe_METHOD.json``), pooled over
stops: the Spearman rank correlation of the two scores over each stop's candidates (median), the chosen
candidate's expected new cells as a share of the best candidate's (median), how often the chosen one is also
the one with the most expected new cells, and the median metres to the chosen candidate against the median
metres to the candidate with the most expected new cells per metre (``+ d_0``).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402
from scipy.stats import spearmanr  # noqa: E402

from ogm_ppl.experiment.tasks import task_env  # noqa: E402
from ogm_ppl.exploration import active as A  # noqa: E402
from ogm_ppl.exploration import information as info  # noqa: E402
from ogm_ppl.grid import Grid  # noqa: E402


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("out", type=Path, help="the --out directory of an active experiment")
    ap.add_argument("--method", default="patch3-ig", help="a sample_info method of the run's spec")
    ap.add_argument("--seed", type=int, default=0, help="the spec seed (default 0)")
    args = ap.parse_args(argv)
    spec = json.loads((args.out / "spec.json").read_text())
    m = next((x for x in spec["methods"] if x["name"] == args.method), None)
    if m is None or m["rule"] != "sample_info":
        raise SystemExit(f"{args.out}: {args.method!r} is not a sample_info method of the spec")
    method = A.Method(**{k: (tuple(v) if k == "patch" and v is not None else v) for k, v in m.items()})
    robot = A.Robot(**spec["robot"])
    rows: list[dict] = []
    original = A._choose

    def probe(method_, robot_, planner, grid, cell, q, q_ogm, samples, observed, *rest, **kw):
        j, cand, inf = original(method_, robot_, planner, grid, cell, q, q_ogm, samples, observed, *rest, **kw)
        if j is None or len(cand) < 3:
            return j, cand, inf
        scan = kw.get("scan_angles")
        sensor, angles, max_range, d0 = rest[1], rest[2], rest[3], rest[4]  # after stops_done (_choose's order)
        mi = info.beam_information(grid, sensor, samples, info.candidate_rays(grid, cand.poses, angles, max_range))
        mi = mi.sum(1).numpy()
        new = info.expected_new_cells(grid, samples, info.candidate_rays(grid, cand.poses, scan, max_range), observed)
        new = new.numpy()
        per_m = new / (cand.distance + d0)
        rows.append(
            {
                "candidates": len(cand),
                "spearman": float(spearmanr(mi, new).statistic),
                "chosen_share_of_best_new": float(new[j] / max(new.max(), 1e-12)),
                "chosen_is_best_new": bool(new[j] == new.max()),
                "chosen_m": float(cand.distance[j]),
                "best_new_per_m_m": float(cand.distance[int(np.argmax(per_m))]),
                "chosen_new_cells": float(new[j]),
                "best_new_cells": float(new.max()),
            }
        )
        return j, cand, inf

    A._choose = probe
    try:
        for pid in [p["id"] for p in json.loads((args.out / "metrics.json").read_text())["plans"]]:
            task = json.loads((args.out / "tasks" / pid / args.method / f"s{args.seed}.json").read_text())
            with np.load(args.out / "plans" / f"{pid}.npz") as z:
                truth, known, res = z["truth"].astype(bool), z["known"].astype(bool), float(z["resolution"])
            n0 = len(rows)
            with task_env():
                run = A.explore(truth, Grid(truth.shape, resolution=res), method, robot, stops=spec["stops"],
                                seed=task["run_seed"], stop_coverage=spec["stop_coverage"], mask=known)  # fmt: skip
            same = run.path_to("coverage", 0.9) == task["path_to"]["coverage"]
            print(f"{pid}: {len(rows) - n0} stops probed; rerun matches the task's path to 90 % coverage: {same}")
            for r in rows[n0:]:
                r["plan"] = pid
    finally:
        A._choose = original
    s = {
        "method": args.method,
        "seed": args.seed,
        "stops": len(rows),
        "median_spearman_info_vs_new_cells": float(np.median([r["spearman"] for r in rows])),
        "median_chosen_share_of_best_new_cells": float(np.median([r["chosen_share_of_best_new"] for r in rows])),
        "share_chosen_is_best_new_cells": float(np.mean([r["chosen_is_best_new"] for r in rows])),
        "median_m_to_chosen": float(np.median([r["chosen_m"] for r in rows])),
        "median_m_to_best_new_cells_per_m": float(np.median([r["best_new_per_m_m"] for r in rows])),
    }
    print(json.dumps(s, indent=1))
    (args.out / f"choice_probe_{args.method}.json").write_text(json.dumps({"summary": s, "stops": rows}, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
