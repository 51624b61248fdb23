r"""What the information-gain rule trades away: at every stop of a ``sample_info`` run, the candidates'
information gain beside their expected newly observed cells, both over the same posterior samples.

The named method of an ``active`` run is rerun (its spec, plans and seeds from the run's folder: the same runs,
since a run is a function of its seed), and at every stop with three or more candidates each candidate ``j`` is
scored by both :func:`~ogm_ppl.exploration.information.beam_information` summed over the beams (bits: what the
rule maximises) and :func:`~ogm_ppl.exploration.information.expected_new_cells` over the scan's beams (``n_j``:
what coverage counts). Pooled over stops: the median Spearman rank correlation of the two scores over each
stop's candidates, the median of the chosen candidate's ``n_j`` as a share of the best ``max_j n_j``, how often
the chosen one is also the one with the most expected new cells, and the median metres ``d_j`` to the chosen
candidate against the median metres to the candidate with the most expected new cells per metre,
``argmax_j n_j / (d_j + d_0)``.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from ogm_ppl.studies.errors import StudyInputError

__all__ = ["active_choice_probe"]


def active_choice_probe(out: str | Path, method: str = "patch3-ig", seed: int = 0) -> dict:
    """The probe of the module docstring on ``method`` (a ``sample_info`` method of the run's spec) of the
    active run in ``out``, spec seed ``seed``: ``{"summary": {...}, "stops": [one dict per stop probed],
    "reruns": {plan: whether the rerun's path to 90 % coverage equals the task's}}``. With its
    ``summary`` and ``stops``, writes ``out/choice_probe_<method>.json``.

    Raises:
        StudyInputError: ``method`` is not a ``sample_info`` method of the run's spec.
    """
    from scipy.stats import spearmanr

    from ogm_ppl.experiment.tasks import task_env
    from ogm_ppl.exploration import active as A
    from ogm_ppl.exploration import information as info
    from ogm_ppl.grid import Grid
    from ogm_ppl.io import atomic_write_text

    out = Path(out)
    spec = json.loads((out / "spec.json").read_text())
    m = next((x for x in spec["methods"] if x["name"] == method), None)
    if m is None or m["rule"] != "sample_info":
        raise StudyInputError(f"{out}: {method!r} is not a sample_info method of the spec")
    kw: dict[str, Any] = {k: (tuple(v) if k == "patch" and v is not None else v) for k, v in m.items()}
    meth = A.Method(**kw)
    robot = A.Robot(**spec["robot"])
    rows: list[dict] = []
    grid: Grid | None = None  # the plan's, while it is explored

    def probe(c: A.Choice) -> None:
        cand, j = c.candidates, c.chosen
        if j is None or len(cand) < 3 or grid is None:
            return
        rays = info.candidate_rays(grid, cand.poses, c.info_angles, c.max_range)
        mi = info.beam_information(grid, c.sensor, c.samples, rays).sum(1).numpy()
        scan = info.candidate_rays(grid, cand.poses, c.scan_angles, c.max_range)
        new = info.expected_new_cells(grid, c.samples, scan, c.observed).numpy()
        per_m = new / (cand.distance + c.d0)
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

    reruns = {}
    for pid in [p["id"] for p in json.loads((out / "metrics.json").read_text())["plans"]]:
        task = json.loads((out / "tasks" / pid / method / f"s{seed}.json").read_text())
        with np.load(out / "plans" / f"{pid}.npz") as z:
            truth, known, res = z["truth"].astype(bool), z["known"].astype(bool), float(z["resolution"])
        grid = Grid(truth.shape, resolution=res)
        n0 = len(rows)
        with task_env():
            run = A.explore(truth, grid, meth, robot, stops=spec["stops"], seed=task["run_seed"],
                            stop_coverage=spec["stop_coverage"], mask=known, on_choice=probe)  # fmt: skip
        reruns[pid] = run.path_to("coverage", 0.9) == task["path_to"]["coverage"]
        for r in rows[n0:]:
            r["plan"] = pid
    s = {
        "method": method,
        "seed": seed,
        "stops": len(rows),
        "median_spearman_info_vs_new_cells": float(np.median([r["spearman"] for r in rows])),
        "median_chosen_share_of_best_new_cells": float(np.median([r["chosen_share_of_best_new"] for r in rows])),
        "share_chosen_is_best_new_cells": float(np.mean([r["chosen_is_best_new"] for r in rows])),
        "median_m_to_chosen": float(np.median([r["chosen_m"] for r in rows])),
        "median_m_to_best_new_cells_per_m": float(np.median([r["best_new_per_m_m"] for r in rows])),
    }
    atomic_write_text(out / f"choice_probe_{method}.json", json.dumps({"summary": s, "stops": rows}, indent=1))
    return {"summary": s, "stops": rows, "reruns": reruns}
