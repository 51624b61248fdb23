"""ogm_ppl.studies.log_plans: a whole-log map becomes a plan without the streaks beams leave outside a building."""

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from ogm_ppl import Grid
from ogm_ppl.datasets.plan_files import load_plan_file
from ogm_ppl.rosmap import load_ros_map, save_ros_map
from ogm_ppl.studies.log_plans import MIN_FREE_CELLS, LogPlanError, clean, log_plans

SCRIPT = Path(__file__).resolve().parents[2] / "experiments" / "log_plans.py"


def _log_map() -> np.ndarray:
    """map_server values: a 20 x 30 free room walled in, a 2-cell streak of free cells leaving it through a
    gap, a separate 6 x 6 free patch (seen through a window), unknown elsewhere."""
    v = np.full((40, 60), -1, np.int8)
    v[4:26, 4:36] = 100
    v[5:25, 5:35] = 0
    v[14:16, 35:58] = 0  # the streak through the gap
    v[30:36, 40:46] = 0  # the patch
    return v


def _write_logs(root: Path, names=("hall", "freiburg-campus")) -> np.ndarray:
    v = _log_map()
    grid = Grid(v.shape, resolution=0.05)
    for name in names:
        p = np.where(v == 100, 1.0, np.where(v == 0, 0.0, np.nan))
        save_ros_map(root / name / "ros" / "map.yaml", p.ravel(), grid, sidecar=False)
    return v


def test_clean_keeps_the_room_and_drops_streaks_and_islands():
    v = _log_map()
    p, unknown = clean(v, 5)
    free = (p == 0) & ~unknown
    assert free[5:25, 5:35].all()  # the room stays whole: a 5 x 5 square fits everywhere in it
    assert not free[14:16, 36:].any()  # the streak is narrower than 5 cells
    assert not free[30:36, 40:46].any()  # a free island apart from the largest component
    np.testing.assert_array_equal(p == 1, v == 100)  # walls stay walls
    np.testing.assert_array_equal(unknown, ~((v == 100) | free))
    p1, unknown1 = clean(v, 1)  # k = 1: no opening, the largest component only
    assert ((p1 == 0) & ~unknown1)[14:16, 35:58].all()


def test_log_plans_writes_plans_the_plan_reader_reads(tmp_path):
    v = _write_logs(tmp_path / "logs")
    plans = log_plans(tmp_path / "logs", tmp_path / "plans")
    assert sorted(f.name for f in (tmp_path / "plans").iterdir()) == ["hall.pgm", "hall.yaml"]  # outdoor left out
    back = load_ros_map(tmp_path / "plans" / "hall.yaml")
    p, unknown = clean(v, MIN_FREE_CELLS)
    np.testing.assert_array_equal(back.occupancy.reshape(v.shape), np.where(unknown, -1, np.where(p == 1, 100, 0)))
    plan = load_plan_file(tmp_path / "plans" / "hall.yaml")
    assert plan.name == "hall" and (~plan.occupancy).sum() == 20 * 30
    [row] = plans
    assert (row.name, row.cols, row.rows) == ("hall", 60, 40)
    assert row.occupied == int((v == 100).sum()) and row.free == 20 * 30
    assert row.yaml == tmp_path / "plans" / "hall.yaml"
    with pytest.raises(LogPlanError, match=r"no <log>/ros/map\.yaml under"):
        log_plans(tmp_path / "nothing", tmp_path / "x")
    with pytest.raises(LogPlanError, match="min_free_cells must be at least 1"):
        log_plans(tmp_path / "logs", tmp_path / "x", min_free_cells=0)
    assert not (tmp_path / "x").exists()
    both = log_plans(tmp_path / "logs", tmp_path / "all", exclude=())
    assert [r.name for r in both] == ["freiburg-campus", "hall"]


def test_the_script_writes_the_library_plans_and_refuses_no_maps(tmp_path):
    _write_logs(tmp_path / "logs")
    ref = log_plans(tmp_path / "logs", tmp_path / "lib")
    r = subprocess.run(
        [sys.executable, str(SCRIPT), "--maps", str(tmp_path / "logs"), "--out", str(tmp_path / "script")],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert r.returncode == 0, r.stderr
    assert (
        r.stdout
        == f"hall: 60 x 40 cells (W x H), {ref[0].occupied:,} occupied, 600 free -> {tmp_path}/script/hall.yaml\n"
    )
    for name in ("hall.yaml", "hall.pgm"):  # the YAML names its image relative to itself
        assert (tmp_path / "script" / name).read_bytes() == (tmp_path / "lib" / name).read_bytes()
    r = subprocess.run(
        [sys.executable, str(SCRIPT), "--maps", str(tmp_path / "nothing")], capture_output=True, text=True, timeout=300
    )
    assert r.returncode == 2 and "no <log>/ros/map.yaml under" in r.stderr
