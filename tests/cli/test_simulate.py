"""``ogm-ppl simulate`` refuses a floor plan with nowhere to put the robot, naming the file and ``--map``."""

import numpy as np
from PIL import Image

from ogm_ppl.cli import main


def _png(path, pixels):
    Image.fromarray(np.asarray(pixels, dtype=np.uint8), "L").save(path)
    return path


def test_a_black_floor_plan_is_refused_naming_the_file_and_the_option(tmp_path, capsys):
    """An all-black plan has no free cell: one error line naming --map, the file and why, before any work; no
    dataset is written."""
    plan = _png(tmp_path / "black.png", np.zeros((40, 50)))
    out = tmp_path / "d.npz"
    assert main(["simulate", "--map", str(plan), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and err.startswith("ogm-ppl: error: argument --map: ")
    assert f"{plan} has no free cell" in err and "50 x 40 pixels" in err
    assert not out.exists()


def test_a_plan_too_narrow_for_the_robot_names_the_file(tmp_path, capsys):
    """Free pixels, but none with the robot's clearance from the walls: the simulation's own reason, prefixed by
    --map and the file."""
    plan = _png(tmp_path / "slit.png", np.pad(np.full((3, 3), 255), 1))
    assert main(["simulate", "--map", str(plan), "--out", str(tmp_path / "d.npz")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith(f"ogm-ppl: error: argument --map: {plan}: no free cell"), err
