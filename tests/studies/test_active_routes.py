"""ogm_ppl.studies.active_routes: step lengths, coverage gains and paths to a level counted on task records made
by hand, the figure, and the methods asked for that have no run; experiments/active_routes.py prints the table."""

import json
import math

import numpy as np
import pytest

from ogm_ppl.studies.active_routes import active_routes, read_runs, route_stats, route_table
from ogm_ppl.studies.errors import StudyInputError
from tests._experiments import run_script


def _task(out, method, plan, seed, paths, covs, f1s):
    d = out / "tasks" / plan / method
    d.mkdir(parents=True, exist_ok=True)
    records = [{"path_length": p, "coverage": c, "f1": f} for p, c, f in zip(paths, covs, f1s)]
    route = [[0.1 + 0.1 * i, 0.2, 0.0] for i in range(len(paths))]
    rec = {"method": method, "plan_id": plan, "seed": seed, "records": records, "route": route}
    rec["path_to"] = {"coverage": math.inf}
    (d / f"s{seed}.json").write_text(json.dumps(rec))


@pytest.fixture
def run(tmp_path):
    _task(tmp_path, "a", "p00", 0, [0, 1, 3], [0.1, 0.5, 0.95], [0.5, 0.8, 0.9])
    _task(tmp_path, "a", "p01", 0, [0, 2], [0.2, 0.205], [0.4, 0.5])
    _task(tmp_path, "b", "p00", 0, [0, 4], [0.1, 0.9], [0.5, 0.95])
    (tmp_path / "plans").mkdir()
    np.savez(tmp_path / "plans" / "p00.npz", truth=np.zeros((20, 20), bool), resolution=0.05)
    return tmp_path


def test_the_steps_and_gains_are_pooled_over_runs(run):
    rows = route_stats(read_runs(run), [0.9])
    a, b = rows
    assert (a["method"], a["runs"], a["stops"]) == ("a", 2, 5)
    assert a["median_step_m"] == 2.0 and a["median_gain_per_stop"] == pytest.approx(0.4)
    assert a["gain_per_metre"] == pytest.approx((0.4 + 0.45 + 0.005) / 5)
    assert a["share_small_steps"] == pytest.approx(1 / 3)
    assert a["path_to_coverage_0.9"] == math.inf and a["reached_coverage_0.9"] == 1  # the median of [3, inf]
    assert (b["path_to_coverage_0.9"], b["path_to_f1_0.9"], b["reached_f1_0.9"]) == (4.0, 4.0, 1)
    assert "| a | 2 | 5 | 2.00 |" in route_table(rows, [0.9]) and "never (1/2)" in route_table(rows, [0.9])


def test_the_study_writes_its_json_and_figure_and_refuses_missing_methods(run):
    rows = active_routes(run, ["b", "a"], [0.9], plan="p00")
    assert [r["method"] for r in rows] == ["b", "a"]
    assert json.loads((run / "route_stats.json").read_text()) == json.loads(json.dumps(rows))
    assert (run / "routes_p00.png").read_bytes()[:4] == b"\x89PNG"
    with pytest.raises(StudyInputError, match="no runs of c"):
        read_runs(run, ["a", "c"])


def test_the_script_prints_the_table(run):
    r = run_script("active_routes.py", run, "--methods", "a", "--levels", "0.9")
    assert r.returncode == 0 and r.stdout.strip() == route_table(route_stats(read_runs(run, ["a"]), [0.9]), [0.9])
    bad = run_script("active_routes.py", run, "--methods", "c")
    assert bad.returncode == 1 and "no runs of c" in bad.stderr
