"""Fixtures of the experiment runner's tests: one serial run of the cut-down smoke spec, and a small CARMEN log
with the ROS bag of the same scans."""

import pytest

from ogm_ppl.experiment import parse_spec, run_experiment
from tests.experiment._smoke import tiny


@pytest.fixture(scope="module")
def serial_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("serial")
    return run_experiment(parse_spec(tiny(), "tiny.toml"), out, scheduler="serial", progress=False)


@pytest.fixture(scope="module")
def room_bag(tmp_path_factory):
    from ogm_ppl.datasets import read_carmen
    from ogm_ppl.datasets.rosbag import write_bag
    from tests.test_cli import write_log

    tmp = tmp_path_factory.mktemp("room")
    log_path = write_log(tmp / "room.log")
    log = read_carmen(log_path, max_usable_range=20.0)
    return log_path, write_bag(tmp / "room.bag", log.scans, log.timestamps)
