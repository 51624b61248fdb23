"""ogm_ppl.calibration.scenes: cells a plan does not know are walls to the simulated sensor and never scored."""

import numpy as np

from ogm_ppl.calibration import CalibrationSettings, make_scene, plan_file_maps


def test_cells_a_plan_does_not_know_are_walls_to_the_sensor_and_never_scored(tmp_path):
    """A map built from a log: a room seen whole, a side room nobody entered (unknown). With
    ``plan_outside="unknown"`` the unknown cells stay unknown: stops never stand in them, no ray crosses them,
    and no mask scores them; by default they are occupied and scored, as the corpora's exteriors are."""
    from scipy import ndimage

    from ogm_ppl import Grid
    from ogm_ppl.rosmap import save_ros_map

    p = np.ones((80, 80))
    p[10:70, 10:45] = 0.0  # the room
    p[30:36, 45:47] = 0.0  # a doorway
    unknown = np.zeros(p.shape, bool)
    unknown[20:60, 47:70] = True  # the room beyond it, never seen
    save_ros_map(tmp_path / "log.yaml", p[::-1].ravel(), Grid(p.shape, resolution=0.05), unknown=unknown[::-1].ravel())
    settings = CalibrationSettings(plan_files=("x",), poses=2, beams=45, range_cells=30.0)
    (t,) = plan_file_maps([tmp_path / "log.yaml"], 1, 96, None, outside="unknown")
    assert not t.known.all() and not t.truth[~t.known].any()
    scene = make_scene(t, settings)
    for mask in scene.masks.values():
        assert not (mask & ~t.known.ravel()).any()
    reached = scene.rays.reached().reshape(t.truth.shape)
    deep = ~ndimage.binary_dilation(t.known, structure=np.ones((3, 3), bool))  # unknown, no known neighbour
    assert deep.any() and (reached & ~t.known).any()  # rays end on the unknown cells next to the room ...
    assert not (reached & deep).any()  # ... as on a wall: none goes deeper
    (t_occ,) = plan_file_maps([tmp_path / "log.yaml"], 1, 96, None)
    assert t_occ.known.all() and t_occ.truth[~t.known].all()
    np.testing.assert_array_equal(t_occ.truth, t.truth | ~t.known)
