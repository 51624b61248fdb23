"""The experiment spec: validation naming the file and key, seeds from names, run hashes, every shipped spec."""

import tomllib
from pathlib import Path

import numpy as np
import pytest

from ogm_ppl.experiment import SpecError, derive_seed, load_spec, parse_spec
from tests.experiment._smoke import SMOKE, bag_spec, tiny


def test_smoke_spec_loads_and_expands():
    spec = load_spec(SMOKE)
    assert [d.name for d in spec.datasets] == ["office-pf1", "office-pf0.5"]
    assert {d.condition for d in spec.datasets} == {"office-pf1", "office-pf0.5"}
    assert [a.name for a in spec.algorithms] == ["ogm", "gibbs-border-L9", "patchmap-L9"]


@pytest.mark.parametrize(
    "edit, message",
    [
        (
            lambda d: d["datasets"][0].update(sigma_cells=-1),
            "datasets[0] ('office').sigma_cells: must be > 0",
        ),
        (
            lambda d: d["datasets"][0].update(sigma_cell=1.0),
            "datasets[0] ('office').sigma_cell: unknown key",
        ),
        (lambda d: d["datasets"][0].pop("kind"), "datasets[0] ('office').kind: is required"),
        (
            lambda d: d["datasets"][0].update(kind="video"),
            "kind: must be one of 'simulated', 'log'",
        ),
        (
            lambda d: d["datasets"][0].update(pose_fraction=[0.5, 0.5]),
            "pose_fraction: lists a value twice",
        ),
        (lambda d: d["datasets"][0].update(name="a b"), "name: may hold only"),
        (
            lambda d: d["algorithms"][1].update(prior="border:nowhere"),
            "algorithms[1] ('gibbs-border-L9').prior:",
        ),
        (lambda d: d["algorithms"][1].update(patch=[9, 9]), "patch: 9 x 9 patches are too large"),
        (lambda d: d["algorithms"][1].update(sweeps=0), "sweeps: must be >= 1"),
        (
            lambda d: d["algorithms"][0].update(delta="nonsense"),
            "algorithms[0] ('ogm').delta: unknown update term",
        ),
        (
            lambda d: d["algorithms"].append(dict(d["algorithms"][0])),
            "the name 'ogm' is used twice",
        ),
        (lambda d: d["metrics"].update(mask="everything"), "metrics.mask: must be one of"),
        (lambda d: d["output"].update(fpfn="some"), "output.fpfn: must be one of"),
        (lambda d: d.update(extras={}), "extras: unknown table"),
        (lambda d: d.update(datasets=[]), "datasets: at least one"),
        (
            lambda d: d["datasets"].append({"name": "x", "kind": "log", "path": "missing.log.gz"}),
            "datasets[1] ('x').path: no such CARMEN log",
        ),
        # grids over the limit are refused when the spec is read
        (lambda d: d["datasets"][0].update(size=200_000), "('office').size: size = [200000, 200000] gives a grid of"),
        (
            lambda d: d["datasets"].append(
                {"name": "x", "kind": "log", "path": str(SMOKE), "extent": [0, 0, 1e5, 1e5]}
            ),
            "('x').extent: [0.0, 0.0, 100000.0, 100000.0] at 0.05 m a cell gives a grid of 2,000,000 x 2,000,000",
        ),
        (
            lambda d: d["experiment"].update(max_cells=1000),
            "size = [64, 64] gives a grid of 64 x 64 = 4,096 cells, over the limit of 1,000 ([experiment] max_cells)",
        ),
    ],
)
def test_spec_errors_name_file_and_key(edit, message):
    d = tomllib.loads(SMOKE.read_text())
    edit(d)
    with pytest.raises(SpecError) as e:
        parse_spec(d, "smoke.toml")
    assert str(e.value).startswith("smoke.toml: ") and message in str(e.value), str(e.value)


def test_bad_toml_and_missing_file(tmp_path):
    p = tmp_path / "bad.toml"
    p.write_text("[experiment\nname = 1")
    with pytest.raises(SpecError, match=r"bad\.toml: not valid TOML"):
        load_spec(p)
    with pytest.raises(SpecError, match="no such spec file"):
        load_spec(tmp_path / "none.toml")


def test_seeds_depend_on_names_not_positions():
    a = derive_seed(7, "run", "office", "ogm", 0)
    assert a == derive_seed(7, "run", "office", "ogm", 0) and 0 <= a < 2**63
    assert (
        len(
            {
                a,
                derive_seed(7, "run", "office", "ogm", 1),
                derive_seed(8, "run", "office", "ogm", 0),
            }
        )
        == 3
    )
    d = tiny()
    d["algorithms"].reverse()  # reordering the spec changes no task's seed
    s1 = {t.id: t.args[3] for t in _plan(tiny()) if t.kind == "run"}
    s2 = {t.id: t.args[3] for t in _plan(d) if t.kind == "run"}
    assert s1 == s2


def _plan(d):
    from ogm_ppl.experiment import plan_tasks

    return plan_tasks(parse_spec(d, "tiny.toml"), Path("/nonexistent"))


def test_rescoring_reruns_no_chain_unless_the_records_change():
    """A sampler's run hash holds what its F1 records depend on (mask as scored, thresholds), not the other
    metrics keys: a new score list, or ``"auto"`` / ``"known"`` for the ``"all"`` they mean on a generated
    map, reruns no chain; new thresholds do."""

    def hashes(**metrics):
        d = tiny()
        d["metrics"] = {**d["metrics"], **metrics}
        return {t.id: t.hash for t in _plan(d) if t.kind == "run"}

    base = hashes()
    assert hashes(scores=["f1", "nll_bits"]) == base
    assert hashes(mask="auto") == base == hashes(mask="known")
    changed = hashes(thresholds=50)
    assert all(changed[k] != v for k, v in base.items() if "gibbs" in k)
    assert all(changed[k] == v for k, v in base.items() if "gibbs" not in k)


@pytest.mark.parametrize(
    "entry, message",
    [
        ({"pose_topic": "/odom", "scan_topic": None}, "datasets[1] ('bag').scan_topic: is required"),
        ({}, "datasets[1] ('bag').tf: give pose_topic or tf = true"),
        ({"pose_topic": "/odom", "tf": True}, "datasets[1] ('bag').pose_topic: give pose_topic or tf = true"),
        ({"tf": True, "laser_offset": [0.1, 0, 0]}, "laser_offset: applies to pose_topic"),
        ({"pose_topic": "/odom", "laser_offset": [0.1, 0]}, "laser_offset: must be [x, y, yaw]"),
        ({"pose_topic": "/odom", "map_frame": "world"}, "map_frame: applies to tf = true"),
        ({"pose_topic": "/odom", "pose_tolerance": -1}, "pose_tolerance: must be >= 0"),
        ({"pose_topic": "/odom", "reader": {"max_usable_range": "20"}}, "reader.max_usable_range: must be a finite"),
        ({"pose_topic": "/odom", "reader": {"no_return": "keep"}}, "reader.no_return: must be one of 'drop', 'max'"),
        ({"pose_topic": "/odom", "reader": {"messages": "auto"}}, "reader.messages: unknown key"),
        ({"pose_topic": "/odom", "reader": {"strict": 1}}, "reader.strict: must be true or false"),
        ({"pose_topic": "/odom", "topic": "/scan"}, "datasets[1] ('bag').topic: unknown key"),
    ],
)
def test_bag_entry_errors_name_the_key(room_bag, entry, message):
    log_path, bag_path = room_bag
    d = bag_spec(log_path, bag_path)
    d["datasets"][1].update(entry)
    d["datasets"][1] = {k: v for k, v in d["datasets"][1].items() if v is not None}
    with pytest.raises(SpecError) as e:
        parse_spec(d, "bags.toml")
    assert str(e.value).startswith("bags.toml: ") and message in str(e.value), str(e.value)
    d = bag_spec(log_path, log_path, pose_topic="/odom")
    with pytest.raises(SpecError, match=r"datasets\[1\] \('bag'\)\.path: not a ROS bag"):
        parse_spec(d, "bags.toml")


@pytest.mark.parametrize(
    "edit, message",
    [
        (lambda d: d.setdefault("experiment", {}).update(name="../escape"), "experiment.name: may hold only"),
        (lambda d: d.setdefault("experiment", {}).update(name="/tmp/abs"), "experiment.name: may hold only"),
        (lambda d: d.setdefault("experiment", {}).update(name="a/b"), "experiment.name: may hold only"),
        (lambda d: d.setdefault("experiment", {}).update(name=".."), "experiment.name: may hold only"),
        (lambda d: d["datasets"][0].update(name=".."), "datasets[0] ('..').name: may hold only"),
        (lambda d: d["algorithms"][0].update(name="..\\x"), "name: may hold only"),
    ],
)
def test_names_that_leave_the_output_folder_are_refused(edit, message):
    """Names become file and folder names under ``--out``: a spec must not be able to write elsewhere."""
    d = tomllib.loads(SMOKE.read_text())
    edit(d)
    with pytest.raises(SpecError) as e:
        parse_spec(d, "smoke.toml")
    assert str(e.value).startswith("smoke.toml: ") and message in str(e.value), str(e.value)


@pytest.mark.parametrize(
    "reader, message",
    [
        ({"max_usable_range": "20"}, "reader.max_usable_range: must be a finite number"),
        ({"max_usable_range": -5.0}, "reader.max_usable_range: must be > 0"),
        ({"no_return_threshold": float("nan")}, "reader.no_return_threshold: must be a finite number"),
        ({"min_range": -1}, "reader.min_range: must be >= 0"),
        ({"strict": "yes"}, "reader.strict: must be true or false"),
        ({"no_return": "keep"}, "reader.no_return: must be one of"),
        ({"no_retrun": "max"}, "reader.no_retrun: unknown key (known here: apply_laser_offset, max_range, "),
    ],
)
def test_reader_options_checked_at_validation(reader, message):
    d = tomllib.loads(SMOKE.read_text())
    d["datasets"].append({"name": "x", "kind": "log", "path": str(SMOKE), "reader": reader})
    with pytest.raises(SpecError) as e:
        parse_spec(d, "smoke.toml")
    assert "datasets[1] ('x')." + message in str(e.value), str(e.value)


def test_a_reader_option_of_the_wrong_type_fails_when_the_spec_is_loaded(tmp_path):
    """``reader = {messages = 5}``: refused by load_spec naming the file, ``reader.messages`` and what it takes
    (the log kind's options, :mod:`ogm_ppl.inputs`), not by a TypeError once the log is read."""
    spec = tmp_path / "messages.toml"
    spec.write_text(
        SMOKE.read_text()
        + f'\n[[datasets]]\nname = "x"\nkind = "log"\npath = "{SMOKE.as_posix()}"\nreader = {{messages = 5}}\n'
    )
    with pytest.raises(SpecError) as e:
        load_spec(spec)
    assert str(e.value) == (
        f"{spec}: datasets[1] ('x').reader.messages: must be 'auto', a laser message type (FLASER, ROBOTLASER1) "
        "or a list of them, got 5"
    )


def test_beam_increment_in_degrees_is_the_multiple_of_the_logs(room_bag):
    from ogm_ppl.datasets import read_carmen

    log_path, bag_path = room_bag
    a = read_carmen(log_path, max_usable_range=20.0).scans.angles
    inc = float(np.degrees(np.diff(np.atleast_2d(a), axis=1)).mean())
    for kind_entry in ({}, {"pose_topic": "/odom"}):
        d = bag_spec(log_path, bag_path, **kind_entry)
        if not kind_entry:
            d["datasets"] = d["datasets"][:1]
        for ds in d["datasets"]:
            ds["beam_increment_deg"] = [2 * inc, 4 * inc]
        spec = parse_spec(d, "inc.toml")
        assert sorted({ds.params["beam_step"] for ds in spec.datasets}) == [2, 4]
    d = bag_spec(log_path, bag_path, pose_topic="/odom")
    d["datasets"] = d["datasets"][:1]
    d["datasets"][0]["beam_increment_deg"] = 2.5 * inc
    with pytest.raises(SpecError, match=r"beam_increment_deg: .* not a multiple of the scans' .*-degree increment"):
        parse_spec(d, "inc.toml")
    d["datasets"][0]["beam_step"] = 2
    with pytest.raises(SpecError, match="beam_step or beam_increment_deg, not both"):
        parse_spec(d, "inc.toml")


@pytest.mark.parametrize("path", sorted(SMOKE.parent.glob("*.toml")), ids=lambda p: p.name)
def test_every_shipped_spec_is_valid(path):
    """Each spec under experiments/specs reads and validates (a renamed parameter or a moved data file would
    otherwise surface only when someone runs it); a spec naming a guide that its docs train first into out/
    may lack only that file."""
    try:
        load_spec(path)
    except SpecError as e:
        assert "no such guide file: out/guides/" in str(e), str(e)
