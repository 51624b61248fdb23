"""The experiment's dataset tasks: ROS bags read like the log, simulated scans of a plan of one's own, a ROS
map's origin yaw, a log over the grid limit."""

import numpy as np
import pytest

from ogm_ppl.experiment import ExperimentError, SpecError, parse_spec, run_experiment
from tests.experiment._smoke import bag_spec, tiny


def test_bag_datasets_run_like_the_log(room_bag, tmp_path):
    log_path, bag_path = room_bag
    spec = parse_spec(bag_spec(log_path, bag_path, pose_topic="/odom"), "bags.toml")
    bag = next(d for d in spec.datasets if d.kind == "bag")
    assert bag.params["bag"]["pose_topic"] == "/odom" and spec.metrics.mask_for("bag") == "near_mapped"
    r = run_experiment(spec, tmp_path / "out", scheduler="serial", progress=False)
    scores = {s["dataset"]: s["mask"] for s in r.scores}
    assert scores["bag"] == scores["log"] and 0.5 < scores["bag"]["best_f1"] <= 1
    with np.load(tmp_path / "out" / "datasets" / "_base" / "log.npz") as a:
        with np.load(tmp_path / "out" / "datasets" / "_base" / "bag.npz") as b:
            assert np.array_equal(a["truth"], b["truth"])
            # the automatic extent follows the hits; a yaw through a quaternion may move one by an ulp
            np.testing.assert_allclose(a["grid"], b["grid"], rtol=0, atol=1e-12)


def test_a_simulated_dataset_on_a_plan_of_your_own(tmp_path):
    """``plan = FILE`` scans a floor plan of your own instead of a generated map: the dataset's truth is the
    plan read at the spec's resolution; generated-map keys are refused beside it, a bad file fails when the
    spec is read (naming the key), and an edited plan is a new dataset."""
    from PIL import Image

    from ogm_ppl.datasets.plan_files import load_plan_file
    from tests._plan_folder import write_plan_folder

    plans = write_plan_folder(tmp_path)
    d = tiny()
    d["datasets"][0] = {
        "name": "mine",
        "kind": "simulated",
        "plan": str(plans / "office.png"),
        "pixel_size": 0.025,
        "poses": 3,
        "beams": 90,
        "max_range_cells": 30,
        "sigma_cells": 1.0,
    }
    d["algorithms"] = [d["algorithms"][0]]  # OGM
    d["metrics"] = {**d["metrics"], "mask": "auto"}  # "known" for simulated data
    r = run_experiment(parse_spec(d, "tiny.toml"), tmp_path / "out", scheduler="serial", progress=False)
    assert not r.failed and "base/mine" in r.executed
    with np.load(tmp_path / "out" / "datasets" / "mine.eval.npz") as z:
        truth, known = z["truth"], z["known"]
    plan = load_plan_file(plans / "office.png", pixel_size=0.025, outside="unknown")
    # the image's top row is the grid's top row (largest y), as in a ROS map
    np.testing.assert_array_equal(truth, np.flipud(plan.occupancy | ~plan.known))
    np.testing.assert_array_equal(known, np.flipud(plan.known))
    assert 0 < known.mean() < 1  # the exterior and the crop's margin are not scored
    from ogm_ppl.experiment.tasks import load_eval

    spec = parse_spec(d, "tiny.toml")
    _, mask, _ = load_eval(tmp_path / "out", spec.datasets[0], spec.metrics)
    np.testing.assert_array_equal(mask, known.ravel())
    again = run_experiment(parse_spec(d, "tiny.toml"), tmp_path / "out", scheduler="serial", progress=False)
    assert again.executed == []
    px = np.asarray(Image.open(plans / "office.png")).copy()
    px[60:64, 20:120] = 0  # a wall added
    Image.fromarray(px).save(plans / "office.png")
    edited = run_experiment(parse_spec(d, "tiny.toml"), tmp_path / "out", scheduler="serial", progress=False)
    assert "base/mine" in edited.executed
    with pytest.raises(SpecError, match=r"datasets\[0\] \('mine'\)\.size: applies to generated maps"):
        parse_spec({**d, "datasets": [{**d["datasets"][0], "size": 80}]}, "tiny.toml")
    (tmp_path / "junk.png").write_bytes(b"no image")
    with pytest.raises(SpecError, match=r"\.plan: .*junk\.png"):
        parse_spec({**d, "datasets": [{**d["datasets"][0], "plan": str(tmp_path / "junk.png")}]}, "tiny.toml")


def test_a_ros_map_plan_with_an_origin_yaw_warns_once(tmp_path):
    """The yaw a ROS map's origin carries is ignored with a warning: once per experiment (when the spec is read),
    not again when the dataset's task reads the plan."""
    import re
    import warnings

    from ogm_ppl.grid import Grid
    from ogm_ppl.rosmap import save_ros_map

    truth = np.zeros((64, 64))
    truth[[0, -1], :] = truth[:, [0, -1]] = truth[30, 10:40] = 1.0
    files = save_ros_map(tmp_path / "plan.yaml", truth, Grid((64, 64), resolution=0.05), sidecar=False)
    text = files.yaml.read_text()
    files.yaml.write_text(re.sub(r"origin: \[([^,]+), ([^,]+), [^\]]+\]", r"origin: [\1, \2, 0.5]", text))
    d = tiny()
    d["datasets"][0] = {
        "name": "ros",
        "kind": "simulated",
        "plan": str(files.yaml),
        "poses": 2,
        "beams": 36,
        "max_range_cells": 20,
        "sigma_cells": 1.0,
    }
    d["algorithms"] = [d["algorithms"][0]]
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        r = run_experiment(parse_spec(d, "tiny.toml"), tmp_path / "out", scheduler="serial", progress=False)
    assert not r.failed
    assert [str(w.message) for w in caught if "origin yaw" in str(w.message)] == [
        f"{files.yaml}: origin yaw 0.5 ignored (ogm_ppl grids are axis-aligned)"
    ]


def test_a_log_whose_grid_is_over_the_limit_is_refused(room_bag, tmp_path):
    """A log's grid is known only once the log is read: its base task refuses it, naming the log and the limit,
    before any map of it is allocated."""
    log_path, _ = room_bag
    d = bag_spec(log_path, log_path)
    d["datasets"] = d["datasets"][:1]
    d["experiment"]["max_cells"] = 100
    with pytest.raises(ExperimentError) as e:
        run_experiment(parse_spec(d, "bags.toml"), tmp_path / "out", scheduler="serial", progress=False)
    assert f"{log_path}: the log's grid at 0.1 m a cell is " in str(e.value)
    assert "over the limit of 100 ([experiment] max_cells; or set the dataset's extent)" in str(e.value)
    assert not (tmp_path / "out" / "datasets" / "_base" / "log.npz").exists()
