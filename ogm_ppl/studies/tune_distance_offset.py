r"""The distance offset ``d_0`` of the per-metre exploration rules, chosen on *validation* plans, never on the
held-out plans the ``active`` experiments score.

A per-metre rule drives to the candidate maximising ``gain_j / (d_j + d_0)`` (``d_j`` metres of path); ``d_0``
trades gain against distance. The protocol: the training plans of the spec's corpus (real-log buildings left
out, natural order) are split as :func:`ogm_ppl.learn.select_headline_prior` and :func:`ogm_ppl.learn.fit_backoff`
split them: every fifth plan (``index % 5 == 4``) is validation. The first ``plans`` validation plans with a
usable window (at least 200 known free cells in the spec's ``window``, cropped as the held-out plans are:
:func:`~ogm_ppl.calibration.usable_windows`) are explored by each named per-metre method of the spec with each
offset, with the spec's robot, stops and stop coverage, one run per plan (seed ``derive_seed(spec seed,
"tune-d0", plan, 0)``, the same for every method and offset). The criterion: the median over the plans of the
path length to 90 % coverage (infinite when a run never reaches it), the mean over the runs that reach it
breaking ties; the smallest such offset wins. The held-out plans are never loaded (and are disjoint from the
training plans by construction of the corpus split). The learned prior's tables were counted on training plans,
which may include these validation plans: the offset is tuned on maps the prior has seen, which can favour the
prior's predictions, but no held-out plan enters the choice.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ogm_ppl.studies._inputs import check_int, check_positive
from ogm_ppl.studies.errors import StudyInputError, StudyOptionError

__all__ = ["tune_distance_offset"]


def _key(paths: list[float]) -> tuple[float, float]:
    """The criterion of a method and offset: (median path, mean over the runs that reach the level)."""
    p = np.array(paths, dtype=float)
    fin = p[np.isfinite(p)]
    return float(np.median(p)), float(fin.mean()) if fin.size else math.inf


def tune_distance_offset(
    spec: str | Path,
    methods: Sequence[str],
    offsets: Sequence[float] = (0.5, 1.0, 2.0, 4.0),
    plans: int = 8,
    *,
    progress: bool = True,
) -> dict:
    """Choose ``d_0`` for each of ``methods`` (per-metre methods of the active ``spec``) among ``offsets``
    (metres) on ``plans`` validation plans (module docstring).

    Returns ``{"spec", "corpus", "window", "validation_plans", "offsets", "criterion", "summary": {method:
    {offset: {"median_path_to_coverage_0.9", "mean_reached"}}}, "chosen": {method: offset}, "runs": [one dict
    per run], "seconds"}``.

    Raises:
        StudyOptionError: a method that is not a per-metre method of the spec, an offset not positive, ``plans``
            below 1.
        StudyInputError: fewer validation plans with a usable window than ``plans``.
    """
    from ogm_ppl.calibration import usable_windows
    from ogm_ppl.datasets import floorplans as fp
    from ogm_ppl.experiment import derive_seed, load_spec
    from ogm_ppl.experiment.tasks import task_env
    from ogm_ppl.exploration.active import Method, Robot, explore
    from ogm_ppl.grid import Grid
    from ogm_ppl.learn._heldout import split_names
    from ogm_ppl.progress import Progress

    check_int(plans, "plans", 1)
    for d0 in offsets:
        check_positive(d0, "offsets")
    sp = load_spec(spec)
    by_name = {m["name"]: m for m in sp.methods}
    for name in methods:
        if name not in by_name or not by_name[name].get("per_metre"):
            raise StudyOptionError("methods", f"{spec}: {name!r} is not a per-metre method of the spec")
    held = set(fp.heldout_plans(sp.corpus))
    _, val = split_names(sp.corpus)
    if held & set(val):
        raise StudyInputError(f"{sp.corpus}: validation plans overlap the held-out plans")
    maps = usable_windows(sp.corpus, val, plans, sp.window)
    if len(maps) < plans:
        raise StudyInputError(f"only {len(maps)} validation plans have a usable window")
    robot = Robot(**sp.robot)
    t0 = time.perf_counter()
    runs: list[dict] = []
    summary: dict[str, dict] = {}
    chosen: dict[str, float] = {}
    total = len(methods) * len(offsets) * len(maps)
    with Progress(total, "exploration runs", unit="run", enabled=progress, after=10.0) as bar:
        for name in methods:
            summary[name] = {}
            for d0 in offsets:
                kw: dict[str, Any] = {
                    k: (tuple(v) if k == "patch" and v is not None else v) for k, v in by_name[name].items()
                }
                m = Method(**{**kw, "distance_offset": float(d0)})
                cov = []
                for t in maps:
                    grid = Grid(t.truth.shape, resolution=t.resolution)
                    seed = derive_seed(sp.seed, "tune-d0", t.name, 0)
                    s0 = time.perf_counter()
                    with task_env():
                        run = explore(t.truth, grid, m, robot, stops=sp.stops, seed=seed,
                                      stop_coverage=sp.stop_coverage, mask=t.known)  # fmt: skip
                    rec = {"method": name, "d0": d0, "plan": t.name,
                           "path_to_coverage_0.9": run.path_to("coverage", 0.9),
                           "path_to_f1_0.9": run.path_to("f1", 0.9), "final_coverage": run.records[-1]["coverage"],
                           "seconds": time.perf_counter() - s0}  # fmt: skip
                    runs.append(rec)
                    cov.append(rec["path_to_coverage_0.9"])
                    bar.update(note=f"{name} d0={d0:g} {t.name}: {rec['path_to_coverage_0.9']:.2f} m")
                med, mean = _key(cov)
                summary[name][f"{d0:g}"] = {"median_path_to_coverage_0.9": med, "mean_reached": mean}
            chosen[name] = min(
                offsets,
                key=lambda d: (
                    *_key([r["path_to_coverage_0.9"] for r in runs if r["method"] == name and r["d0"] == d]),
                    d,
                ),
            )
    return {
        "spec": str(spec),
        "corpus": sp.corpus,
        "window": sp.window,
        "validation_plans": [t.name for t in maps],
        "offsets": list(offsets),
        "criterion": "median over validation plans of the path length to 90 % coverage (ties: mean over reached)",
        "summary": summary,
        "chosen": chosen,
        "runs": runs,
        "seconds": time.perf_counter() - t0,
    }
