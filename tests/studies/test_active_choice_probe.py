"""ogm_ppl.studies.active_choice_probe: a method that is not a sample_info method of the run's spec is refused
before anything runs; explore's on_choice hook sees every choice (the probe's rerun is checked on a real run by
the script's own output: "rerun matches the task's path"); experiments/active_choice_probe.py has its options."""

import json

import numpy as np
import pytest

from ogm_ppl.exploration.active import Choice, Method, Robot, explore
from ogm_ppl.grid import Grid
from ogm_ppl.studies.active_choice_probe import active_choice_probe
from ogm_ppl.studies.errors import StudyInputError
from tests._experiments import run_script


def test_a_method_that_is_not_sample_info_is_refused(tmp_path):
    spec = {"methods": [{"name": "frontier", "rule": "frontier"}], "robot": {}}
    (tmp_path / "spec.json").write_text(json.dumps(spec))
    for method in ("frontier", "other"):
        with pytest.raises(StudyInputError, match=f"'{method}' is not a sample_info method"):
            active_choice_probe(tmp_path, method)
    assert [p.name for p in tmp_path.iterdir()] == ["spec.json"]


def test_the_hook_sees_each_choice_and_changes_nothing():
    truth = np.zeros((30, 30), bool)
    truth[[0, -1], :] = truth[:, [0, -1]] = True
    truth[5:25, 15] = True
    grid = Grid(truth.shape, resolution=0.05)
    robot = Robot(beams=45, max_range_cells=12, stride=4)
    method = Method("ogm-ig", "ogm_info")
    seen: list[Choice] = []
    run = explore(truth, grid, method, robot, stops=3, seed=0, on_choice=seen.append)
    plain = explore(truth, grid, method, robot, stops=3, seed=0)
    assert np.array_equal(run.route, plain.route) and len(seen) == len(run.records) - (run.stopped != "no candidate")
    assert [c.stop for c in seen] == list(range(len(seen)))
    for c, rec in zip(seen, run.records[1:]):
        assert c.chosen is not None and rec["candidates"] == len(c.candidates) and c.samples is None


def test_the_script_has_its_options():
    r = run_script("active_choice_probe.py", "--help")
    assert r.returncode == 0 and "--method" in r.stdout and "--seed" in r.stdout, r.stderr
