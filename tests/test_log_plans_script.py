"""experiments/log_plans.py: a whole-log map becomes a plan without the streaks beams leave outside a building."""

import sys

import numpy as np
import pytest

from ogm_ppl import Grid
from ogm_ppl.datasets.plan_files import load_plan_file
from ogm_ppl.rosmap import load_ros_map, save_ros_map
from tests._scripts import load_experiment


@pytest.fixture(scope="module")
def lp():
    mod = load_experiment("log_plans_experiment", "log_plans.py")
    yield mod
    sys.modules.pop("log_plans_experiment", None)


def _log_map() -> np.ndarray:
    """map_server values: a 20 x 30 free room walled in, a 2-cell streak of free cells leaving it through a
    gap, a separate 6 x 6 free patch (seen through a window), unknown elsewhere."""
    v = np.full((40, 60), -1, np.int8)
    v[4:26, 4:36] = 100
    v[5:25, 5:35] = 0
    v[14:16, 35:58] = 0  # the streak through the gap
    v[30:36, 40:46] = 0  # the patch
    return v


def test_clean_keeps_the_room_and_drops_streaks_and_islands(lp):
    v = _log_map()
    p, unknown = lp.clean(v, 5)
    free = (p == 0) & ~unknown
    assert free[5:25, 5:35].all()  # the room stays whole: a 5 x 5 square fits everywhere in it
    assert not free[14:16, 36:].any()  # the streak is narrower than 5 cells
    assert not free[30:36, 40:46].any()  # a free island apart from the largest component
    np.testing.assert_array_equal(p == 1, v == 100)  # walls stay walls
    np.testing.assert_array_equal(unknown, ~((v == 100) | free))
    p1, unknown1 = lp.clean(v, 1)  # k = 1: no opening, the largest component only
    assert ((p1 == 0) & ~unknown1)[14:16, 35:58].all()


def test_main_writes_plans_the_plan_reader_reads(lp, tmp_path):
    v = _log_map()
    grid = Grid(v.shape, resolution=0.05)
    for name in ("hall", "freiburg-campus"):
        p = np.where(v == 100, 1.0, np.where(v == 0, 0.0, np.nan))
        save_ros_map(tmp_path / "logs" / name / "ros" / "map.yaml", p.ravel(), grid, sidecar=False)
    assert lp.main(["--maps", str(tmp_path / "logs"), "--out", str(tmp_path / "plans")]) == 0
    assert sorted(f.name for f in (tmp_path / "plans").iterdir()) == ["hall.pgm", "hall.yaml"]  # outdoor left out
    back = load_ros_map(tmp_path / "plans" / "hall.yaml")
    p, unknown = lp.clean(v, lp.MIN_FREE_CELLS)
    np.testing.assert_array_equal(back.occupancy.reshape(v.shape), np.where(unknown, -1, np.where(p == 1, 100, 0)))
    plan = load_plan_file(tmp_path / "plans" / "hall.yaml")
    assert plan.name == "hall" and (~plan.occupancy).sum() == 20 * 30
    with pytest.raises(SystemExit):
        lp.main(["--maps", str(tmp_path / "nothing"), "--out", str(tmp_path / "x")])
