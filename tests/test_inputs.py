"""The input kinds (:mod:`ogm_ppl.inputs`): every shipped kind and one of one's own pass
:class:`~ogm_ppl.testing.InputKindContract`; a kind of one's own is told apart, read by ``ogm-ppl map`` and named
by a spec; the table refuses what it must."""

import json
from dataclasses import dataclass

import numpy as np
import pytest

from ogm_ppl.cli import main
from ogm_ppl.inputs import (
    InputData,
    InputError,
    InputKind,
    detect_input_kind,
    get_input_kind,
    input_kinds,
    read_input,
    register_input_kind,
    unregister_input_kind,
)
from ogm_ppl.options import Float, ParamError, param
from ogm_ppl.scans import Scans
from ogm_ppl.testing import InputKindContract
from tests.test_cli import write_log


class TestLog(InputKindContract):
    kind = "log"
    other_options = {"max_usable_range": 5.0}

    def make_input(self, folder):
        return write_log(folder / "tiny.log"), {"max_usable_range": 20.0}


class TestBag(InputKindContract):
    kind = "bag"
    other_options = {"beam_step": 2}

    def make_input(self, folder):
        from ogm_ppl.datasets import read_carmen
        from ogm_ppl.datasets.rosbag import write_bag

        log = read_carmen(write_log(folder / "tiny.log"), max_usable_range=20.0)
        bag = write_bag(folder / "tiny_mcap", log.scans, log.timestamps, storage="mcap")  # a ROS 2 bag folder
        return bag, {"scan_topic": "/scan", "pose_topic": "/odom"}


class TestDatasetFile(InputKindContract):
    kind = "npz"
    other_options = {"pose_fraction": 0.5}

    def make_input(self, folder):
        from ogm_ppl.datasets import read_carmen, save_dataset

        log = read_carmen(write_log(folder / "tiny.log"), max_usable_range=20.0)
        save_dataset(folder / "tiny.npz", log.scans, grid=log.grid(0.1))
        return folder / "tiny.npz", {}


class TestSimulated(InputKindContract):
    kind = "simulated"
    other_options = {"seed": 1}

    def make_input(self, folder):
        return None, {"size": 60, "border": 5, "poses": 2, "beams": 36, "max_range_cells": 20}


# ------------------------------------------------------------------------------- a kind of one's own
@dataclass(frozen=True)
class CsvOptions:
    max_range: float = param(30.0, Float(0, lo_open=True), "the sensor's maximum range (metres)")


def read_csv_scans(path, options):
    """One scan a line: x, y, yaw, then the ranges of beams evenly spread over 360 degrees."""
    rows = np.loadtxt(path, delimiter=",", ndmin=2)
    angles = np.linspace(-np.pi, np.pi, rows.shape[1] - 3, endpoint=False)
    scans = Scans(rows[:, :3], angles, rows[:, 3:], options.max_range, over_range="max")
    return InputData("csv", path, scans, settings={"max_range": options.max_range})


CSV = InputKind(
    "csv",
    CsvOptions,
    read_csv_scans,
    "scans as CSV lines",
    noun="CSV scan file",
    detect=lambda path, head: path.suffix == ".csv",
)


def write_csv(path):
    ranges = 1.5 + 0.5 * np.abs(np.sin(np.linspace(0, 6, 36)))
    lines = [",".join(map(str, [x, 0.2 * x, 0.0, *ranges])) for x in (0.0, 0.3, 0.6)]
    path.write_text("\n".join(lines) + "\n")
    return path


@pytest.fixture
def csv_kind():
    register_input_kind(CSV)
    yield CSV
    unregister_input_kind("csv")


class TestCsv(InputKindContract):
    kind = "csv"
    other_options = {"max_range": 10.0}

    @pytest.fixture(autouse=True)
    def _registered(self, csv_kind):
        yield

    def make_input(self, folder):
        return write_csv(folder / "scans.csv"), {"max_range": 5.0}


def test_a_kind_of_ones_own_is_mapped_by_the_command_line_and_named_by_a_spec(csv_kind, tmp_path, capsys):
    from ogm_ppl.experiment import parse_spec, run_experiment

    path = write_csv(tmp_path / "scans.csv")
    assert detect_input_kind(path) == "csv" and "csv" in input_kinds()
    assert main(["map", str(path), "--resolution", "0.1", "--out", str(tmp_path / "map")]) == 0
    report = json.loads((tmp_path / "map" / "report.json").read_text())
    assert report["input"]["kind"] == "csv" and report["counts"]["scans"] == 3
    assert main(["map", str(path), "--lenient", "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert f"--lenient applies to CARMEN logs and ROS bags; {path} is a CSV scan file" in err, err
    spec = {
        "datasets": [{"name": "csv", "kind": "csv", "path": str(path), "max_range": 4.0, "resolution": 0.1}],
        "algorithms": [{"name": "ogm", "kind": "ogm"}],
        "output": {"maps": False, "figures": False},
    }
    parsed = parse_spec(spec, "csv.toml")
    assert parsed.datasets[0].params["csv"] == {"max_range": 4.0} and parsed.metrics.mask_for("csv") == "near_mapped"
    r = run_experiment(parsed, tmp_path / "exp", scheduler="serial", progress=False)
    assert not r.failed and [s["dataset"] for s in r.scores] == ["csv"]
    from ogm_ppl.experiment import SpecError

    with pytest.raises(SpecError, match=r"datasets\[0\] \('csv'\)\.max_range: must be > 0, got -1"):
        parse_spec({**spec, "datasets": [{**spec["datasets"][0], "max_range": -1}]}, "csv.toml")


def test_a_dataset_file_is_an_experiments_dataset(tmp_path):
    from ogm_ppl.experiment import parse_spec, run_experiment

    path, _ = TestDatasetFile().make_input(tmp_path)
    spec = {
        "datasets": [{"name": "file", "kind": "npz", "path": str(path), "resolution": 0.1, "beam_step": [1, 2]}],
        "algorithms": [{"name": "ogm", "kind": "ogm"}],
        "output": {"maps": False, "figures": False},
    }
    r = run_experiment(parse_spec(spec, "npz.toml"), tmp_path / "exp", scheduler="serial", progress=False)
    assert not r.failed and sorted(s["dataset"] for s in r.scores) == ["file-bs1", "file-bs2"]
    with pytest.raises(ValueError, match=r"reader\.strict: unknown key \(a dataset file takes no reader options\)"):
        parse_spec({**spec, "datasets": [{**spec["datasets"][0], "reader": {"strict": False}}]}, "npz.toml")


def test_the_table_refuses_what_it_must(csv_kind, tmp_path):
    with pytest.raises(ValueError, match="input kind 'csv' is already registered"):
        register_input_kind(InputKind("csv", CsvOptions, lambda path, options: None, "another", noun="x"))
    with pytest.raises(ValueError, match="'log' is a shipped input kind"):
        unregister_input_kind("log")
    with pytest.raises(ValueError, match=r"unknown input kind 'nope'; kinds: log, bag, npz, simulated, .*csv"):
        get_input_kind("nope")
    with pytest.raises(TypeError, match="make parameter fields with param"):

        @dataclass(frozen=True)
        class Bare:
            x: int = 1

        register_input_kind(InputKind("bare", Bare, read_csv_scans, "bare", noun="bare file"))
    with pytest.raises(InputError, match="no such file"):
        detect_input_kind(tmp_path / "missing.log")
    with pytest.raises(InputError, match="reads a CARMEN log: give its path"):
        read_input("log")


@pytest.mark.parametrize(
    "kind, values, key, message",
    [
        ("log", {"messages": 5}, "messages", "must be 'auto', a laser message type (FLASER, ROBOTLASER1) or a list"),
        ("log", {"messages": ["FLASER", "FLASER"]}, "messages", "must be 'auto'"),
        ("log", {"pose_step": 2, "pose_fraction": 0.5}, "pose_fraction", "give pose_step or pose_fraction, not both"),
        ("bag", {"scan_topic": "/s", "tf": True, "laser_offset": [0, 0, 0]}, "laser_offset", "applies to pose_topic"),
        ("bag", {"scan_topic": "/s", "pose_topic": "/o", "map_frame": "w"}, "map_frame", "applies to tf = true"),
        (
            "bag",
            {"scan_topic": "/s", "pose_topic": "/o", "laser_offset": [0, 0]},
            "laser_offset",
            "must be [x, y, yaw]",
        ),
        ("simulated", {"plan": "p.png", "size": 80}, "size", "applies to generated maps, not to a plan"),
        ("simulated", {"size": 60, "border": 16}, "border", "must be <= 15, got 16"),
        ("simulated", {"beams": 4, "beam_step": 5}, "beam_step", "5 exceeds beams = 4"),
    ],
)
def test_options_are_checked_when_read_naming_the_key(kind, values, key, message):
    with pytest.raises(ParamError) as e:
        get_input_kind(kind).parse(values)
    assert e.value.key == key and message in e.value.message, str(e.value)


def test_messages_name_options_as_each_surface_does():
    with pytest.raises(ParamError) as e:
        get_input_kind("bag").parse({"scan_topic": "/s", "tf": True, "laser_offset": [0, 0, 0]})
    assert e.value.message == "applies to pose_topic; with tf = true the mounting comes from /tf_static"
    flag = e.value.message_naming(lambda k: "--" + k.replace("_", "-"))
    assert flag == "applies to --pose-topic; with --tf the mounting comes from /tf_static"


def test_reader_flags_are_the_kinds_options(tmp_path, capsys):
    """A flag is refused for an input whose kind lacks its option, and the rules between options are the kind's,
    named by their flags."""
    bag, _ = TestBag().make_input(tmp_path)
    log = tmp_path / "tiny.log"
    cases = [
        (["map", bag, "--pose-topic", "/odom", "--map-frame", "world"], "--map-frame applies to --tf"),
        (["map", log, "--tf"], f"--tf applies to ROS bags; {log} is a CARMEN log"),
        (["info", log, "--pose-tolerance", "0.5"], "--pose-tolerance applies to ROS bags"),
    ]
    for argv, expected in cases:
        argv = [*map(str, argv), *(["--out", str(tmp_path / "o")] if argv[0] == "map" else [])]
        assert main(argv) == 2
        err = capsys.readouterr().err
        assert err.startswith("ogm-ppl: error: ") and expected in err, (argv, err)
