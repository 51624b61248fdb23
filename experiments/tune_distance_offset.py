r"""Choose the distance offset ``d_0`` of the per-metre exploration rules on *validation* plans, never on the
held-out plans the ``active`` experiments score.

    python experiments/tune_distance_offset.py experiments/specs/active_medium.toml \
        --methods patch3-cov-per-m indep-cov-per-m --offsets 0.5 1 2 4 --plans 8 --out out/tune_d0.json

The protocol. The training plans of the spec's corpus (``training_plans``, real-log buildings left out, natural
order) are split as ``select_headline_prior.py`` and ``fit_backoff.py`` split them: every fifth plan
(``index % 5 == 4``) is *validation*. The first ``--plans`` validation plans with a usable window (at least 200
known free cells in the spec's ``window``, cropped as the held-out plans are: ``calibration.usable_windows``)
are explored by each named per-metre method of the spec with each offset ``d_0`` in ``--offsets`` (metres),
with the spec's robot, stops and stop coverage, one run per plan (seed ``derive_seed(spec seed, "tune-d0",
plan)``, the same for every method and offset). The criterion: the median over the plans of the path length to
90 % coverage (inf when a run never reaches it), the mean path to it over the runs that reach it breaking ties;
the smallest such offset wins. The held-out plans are never loaded (and are disjoint from the training plans by
construction of the corpus split). The learned prior's tables were counted on training plans, which may
include these validation plans: the offset is tuned on maps the prior has seen, which can favour the prior's
predictions, but no held-out plan enters the choice.

Writes ``--out`` (JSON): every run's path to 90 % coverage and to F1 0.9, the per-offset summary and the chosen
offset per method, with the validation plans used.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "experiments"))

import numpy as np  # noqa: E402
from select_headline_prior import split_names  # noqa: E402

from ogm_ppl.calibration import usable_windows  # noqa: E402
from ogm_ppl.datasets import floorplans as fp  # noqa: E402
from ogm_ppl.experiment import derive_seed, load_spec  # noqa: E402
from ogm_ppl.experiment.tasks import task_env  # noqa: E402
from ogm_ppl.exploration.active import Method, Robot, explore  # noqa: E402
from ogm_ppl.grid import Grid  # noqa: E402
from ogm_ppl.io import atomic_write_text  # noqa: E402


def _key(paths: list[float]) -> tuple[float, float]:
    p = np.array(paths, dtype=float)
    fin = p[np.isfinite(p)]
    return float(np.median(p)), float(fin.mean()) if fin.size else math.inf


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("spec", type=Path, help="an active spec (robot, stops, corpus, window and the methods)")
    ap.add_argument("--methods", nargs="+", required=True, help="per-metre methods of the spec to tune")
    ap.add_argument("--offsets", nargs="+", type=float, default=[0.5, 1.0, 2.0, 4.0], help="d_0 values (m)")
    ap.add_argument("--plans", type=int, default=8, help="validation plans (default 8)")
    ap.add_argument("--out", type=Path, default=Path("out/tune_distance_offset.json"))
    args = ap.parse_args(argv)
    spec = load_spec(args.spec)
    by_name = {m["name"]: m for m in spec.methods}
    for name in args.methods:
        if name not in by_name or not by_name[name].get("per_metre"):
            raise SystemExit(f"{args.spec}: {name!r} is not a per-metre method of the spec")
    held = set(fp.heldout_plans(spec.corpus))
    _, val = split_names(spec.corpus)
    assert not held & set(val), "validation plans overlap the held-out plans"
    maps = usable_windows(spec.corpus, val, args.plans, spec.window)
    if len(maps) < args.plans:
        raise SystemExit(f"only {len(maps)} validation plans have a usable window")
    robot = Robot(**spec.robot)
    t0 = time.perf_counter()
    runs, summary, chosen = [], {}, {}
    for name in args.methods:
        summary[name] = {}
        for d0 in args.offsets:
            kw = {k: (tuple(v) if k == "patch" and v is not None else v) for k, v in by_name[name].items()}
            m = Method(**{**kw, "distance_offset": float(d0)})
            cov = []
            for t in maps:
                grid = Grid(t.truth.shape, resolution=t.resolution)
                seed = derive_seed(spec.seed, "tune-d0", t.name, 0)
                s0 = time.perf_counter()
                with task_env():
                    run = explore(t.truth, grid, m, robot, stops=spec.stops, seed=seed,
                                  stop_coverage=spec.stop_coverage, mask=t.known)  # fmt: skip
                rec = {"method": name, "d0": d0, "plan": t.name, "path_to_coverage_0.9": run.path_to("coverage", 0.9),
                       "path_to_f1_0.9": run.path_to("f1", 0.9), "final_coverage": run.records[-1]["coverage"],
                       "seconds": time.perf_counter() - s0}  # fmt: skip
                runs.append(rec)
                cov.append(rec["path_to_coverage_0.9"])
                print(f"{name} d0={d0:g} {t.name}: {rec['path_to_coverage_0.9']:.2f} m ({rec['seconds']:.1f} s)",
                      flush=True)  # fmt: skip
            med, mean = _key(cov)
            summary[name][f"{d0:g}"] = {"median_path_to_coverage_0.9": med, "mean_reached": mean}
        best = min(args.offsets, key=lambda d: (*_key([r["path_to_coverage_0.9"] for r in runs
                                                         if r["method"] == name and r["d0"] == d]), d))  # fmt: skip
        chosen[name] = best
        print(f"{name}: chosen d0 = {best:g} m", flush=True)
    doc = {
        "spec": str(args.spec),
        "corpus": spec.corpus,
        "window": spec.window,
        "validation_plans": [t.name for t in maps],
        "offsets": args.offsets,
        "criterion": "median over validation plans of the path length to 90 % coverage (ties: mean over reached)",
        "summary": summary,
        "chosen": chosen,
        "runs": runs,
        "seconds": time.perf_counter() - t0,
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_text(args.out, json.dumps(doc, indent=1, allow_nan=True))
    print(args.out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
