"""The experiment runner: spec validation, serial == dask bit for bit, resume, outputs."""

import json
import tomllib
from pathlib import Path

import numpy as np
import pytest

from ogm_ppl.experiment import ExperimentError, SpecError, derive_seed, load_spec, parse_spec, run_experiment
from ogm_ppl.experiment import tasks as T

SMOKE = Path(__file__).resolve().parents[2] / "experiments" / "specs" / "smoke.toml"


def tiny(**output) -> dict:
    """The smoke spec cut down for tests: one dataset, OGM and a 2-chain border-prior Gibbs run."""
    d = tomllib.loads(SMOKE.read_text())
    d["datasets"][0]["pose_fraction"] = 1.0
    d["algorithms"] = [d["algorithms"][0], d["algorithms"][1]]
    d["output"] = {"maps": False, "figures": False, **output}
    return d


@pytest.fixture(scope="module")
def serial_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("serial")
    return run_experiment(parse_spec(tiny(), "tiny.toml"), out, scheduler="serial", progress=False)


def _numbers(out: Path) -> dict:
    m = json.loads((out / "metrics.json").read_text())
    runs = [
        {k: v for k, v in r.items() if k not in ("seconds", "trace", "resumed_from_sweep", "resumed_seconds")}
        for r in m["runs"]
    ]
    traces = [[{k: v for k, v in t.items() if k != "seconds"} for t in r.get("trace", [])] for r in m["runs"]]
    maps = {str(p.relative_to(out)): np.load(p)["marginals"] for p in sorted(out.glob("tasks/**/marginals.npz"))}
    return {
        "scores": m["scores"],
        "pooled": m["pooled"],
        "runs": runs,
        "traces": traces,
        "maps": maps,
    }


def _same(a: dict, b: dict) -> None:
    assert a["scores"] == b["scores"] and a["pooled"] == b["pooled"]
    assert a["runs"] == b["runs"] and a["traces"] == b["traces"]
    assert a["maps"].keys() == b["maps"].keys()
    for k in a["maps"]:
        assert np.array_equal(a["maps"][k], b["maps"][k]), k


# ------------------------------------------------------------------------------------------ spec
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


# ------------------------------------------------------------------------------------------ runs
def test_serial_run_writes_outputs(serial_run, tmp_path):
    out = serial_run.out_dir
    for f in (
        "metrics.json",
        "metrics.md",
        "spec.json",
        "datasets/office.npz",
        "datasets/office.eval.npz",
        "maps/office/ogm.npz",
        "tasks/office/gibbs-border-L9/c1/result.json",
    ):
        assert (out / f).exists(), f
    assert not list(out.glob("tasks/**/gibbs.npz")), "spent checkpoints are removed"
    s = {(r["dataset"], r["algorithm"]): r for r in serial_run.scores}
    for r in s.values():
        assert 0.5 < r["mask"]["best_f1"] <= 1 and 0.5 < r["mask"]["auc"] <= 1 and "best_f1" in r["touched"]
    g = next(r for r in serial_run.runs if r["algorithm"] == "gibbs-border-L9")
    assert [t["sweep"] for t in g["trace"]] == [4, 6, 8] and all("f1" in t for t in g["trace"])
    md = (out / "metrics.md").read_text()
    assert "| ogm |" in md and "| gibbs-border-L9 |" in md


def test_figures_and_maps(tmp_path):
    d = tiny(maps=True, figures=True, dpi=30)
    d["datasets"][0]["pose_fraction"] = [1.0, 0.5]
    d["algorithms"][1].update(sweeps=2, burn_in=0, chains=1, record=2)
    r = run_experiment(parse_spec(d, "fig.toml"), tmp_path, scheduler="serial", progress=False)
    names = {p.name for p in (tmp_path / "figures").glob("*.png")}
    for n in (
        "pr_office-pf1.png",
        "f1_threshold_office-pf0.5.png",
        "f1_sparsity_office.png",
        "fpfn_office-pf1.png",
        "fpfn_thresholds_office-pf0.5.png",
        "f1_time_office-pf1.png",
    ):
        assert n in names, n
    assert (tmp_path / "tasks/office-pf1/ogm/c0/map.png").exists() and (tmp_path / "maps/office-pf1/ogm.png").exists()
    assert len(r.pooled) == 4


def test_serial_equals_two_worker_local_cluster(serial_run, tmp_path):
    r = run_experiment(parse_spec(tiny(), "tiny.toml"), tmp_path, workers=2, progress=False)
    assert not r.failed and not r.skipped
    _same(_numbers(serial_run.out_dir), _numbers(tmp_path))


def test_resume_skips_finished_tasks_and_reruns_missing(serial_run, tmp_path):
    import shutil

    out = tmp_path / "copy"
    shutil.copytree(serial_run.out_dir, out)
    spec = parse_spec(tiny(), "tiny.toml")
    r = run_experiment(spec, out, scheduler="serial", progress=False)
    assert r.executed == [] and len(r.skipped) == 7
    (out / "tasks/office/gibbs-border-L9/c1/result.json").unlink()
    r = run_experiment(spec, out, scheduler="serial", progress=False)
    assert r.executed == ["run/office/gibbs-border-L9/c1", "score/office/gibbs-border-L9"]
    _same(_numbers(serial_run.out_dir), _numbers(out))
    d = tiny()
    d["algorithms"][0]["prior"] = 0.4  # a changed entry is recomputed, with its dependants only
    r = run_experiment(parse_spec(d, "tiny.toml"), out, scheduler="serial", progress=False)
    assert r.executed == ["run/office/ogm/c0", "score/office/ogm"]


def test_a_prior_changed_under_its_name_is_rerun(tmp_path):
    """A registered prior whose tables change between two runs (tables of your own counted anew) has the same
    name in the spec: its runs are recomputed, not found done; an unchanged prior's are found done."""
    from ogm_ppl.priors import IndependentPrior, register_prior, unregister_prior

    state = {"lam": 0.3}
    register_prior("test_changing", lambda shape, tables: IndependentPrior(state["lam"], int(np.prod(shape))))
    try:
        d = tiny()
        d["algorithms"] = [{"name": "gibbs-mine", "kind": "gibbs", "prior": "test_changing", "sweeps": 3}]
        spec = parse_spec(d, "tiny.toml")
        first = run_experiment(spec, tmp_path, scheduler="serial", progress=False)
        assert "run/office/gibbs-mine/c0" in first.executed
        again = run_experiment(spec, tmp_path, scheduler="serial", progress=False)
        assert again.executed == []
        state["lam"] = 0.6
        changed = run_experiment(spec, tmp_path, scheduler="serial", progress=False)
        assert changed.executed == ["run/office/gibbs-mine/c0", "score/office/gibbs-mine"]
    finally:
        unregister_prior("test_changing")


def test_interrupted_gibbs_task_resumes_bit_for_bit(serial_run, tmp_path):
    import shutil

    out = tmp_path / "copy"
    shutil.copytree(serial_run.out_dir, out)
    spec = parse_spec(tiny(), "tiny.toml")
    task = next(
        t
        for t in __import__("ogm_ppl.experiment", fromlist=["plan_tasks"]).plan_tasks(spec, out)
        if t.id == "run/office/gibbs-border-L9/c0"
    )
    task.done_file.unlink()
    assert T.run_algorithm(*task.args, stop_after=3) is None  # "killed" after 3 of 8 sweeps
    folder = task.done_file.parent
    assert (folder / "gibbs.npz").exists() and not task.done_file.exists()
    r = run_experiment(spec, out, scheduler="serial", progress=False)
    assert r.executed == ["run/office/gibbs-border-L9/c0", "score/office/gibbs-border-L9"]
    res = json.loads(task.done_file.read_text())
    assert res["resumed_from_sweep"] == 3
    assert res["seconds"] > res["resumed_seconds"] > 0  # the run's time counts the stopped call's sampling
    _same(_numbers(serial_run.out_dir), _numbers(out))


def test_ogm_update_terms_fitted_for_the_sensor_setting_or_warned(tmp_path):
    """The smoke dataset's sensor (sigma 1 cell, 30-cell range) is not the shipped p21's (sigma 3, F 75):
    used as shipped it warns and the warning is kept; ``fit = "setting"`` refits p21 there (Section 2.5)."""
    from ogm_ppl.inference.variational import FittedSettingWarning

    d = tiny()
    d["algorithms"] = [
        {"name": "p21", "kind": "ogm", "delta": "p21"},
        {"name": "p21-fit", "kind": "ogm", "delta": "p21", "fit": "setting"},
    ]
    with pytest.warns(FittedSettingWarning, match="p21"):
        r = run_experiment(parse_spec(d, "fit.toml"), tmp_path, scheduler="serial", progress=False)
    runs = {x["algorithm"]: x for x in r.runs}
    assert runs["p21"]["delta_setting"] == {"sigma_cells": 1.0, "F_cells": 30}
    assert any("sigma" in w for w in runs["p21"]["warnings"])
    fitted = runs["p21-fit"]["delta_fitted"]
    assert (fitted["sigma"], fitted["F"]) == (1.0, 30) and "warnings" not in runs["p21-fit"]
    assert len(list((tmp_path / "deltas").glob("delta_p21_sigma1_F30_*.json"))) == 1  # cached for reruns
    with pytest.raises(SpecError, match="cannot refit 'haehnel'"):
        parse_spec({**d, "algorithms": [{"name": "h", "kind": "ogm", "delta": "haehnel", "fit": "setting"}]}, "x")


# ------------------------------------------------------------------------------------------ ROS bags
def _bag_spec(log_path: Path, bag_path: Path, **bag_entry) -> dict:
    """One log entry and one bag entry holding the same scans, and traditional OGM."""
    common = {"resolution": 0.1, "sigma_cells": 1.0, "reader": {"max_usable_range": 20.0}}
    return {
        "experiment": {"name": "bags"},
        "datasets": [
            {"name": "log", "kind": "log", "path": str(log_path), **common},
            {"name": "bag", "kind": "bag", "path": str(bag_path), "scan_topic": "/scan", **common, **bag_entry},
        ],
        "algorithms": [{"name": "ogm", "kind": "ogm", "delta": "haehnel"}],
        "output": {"maps": False, "figures": False},
    }


@pytest.fixture(scope="module")
def room_bag(tmp_path_factory):
    from ogm_ppl.datasets import read_carmen
    from ogm_ppl.datasets.rosbag import write_bag
    from tests.test_cli import write_log

    tmp = tmp_path_factory.mktemp("room")
    log_path = write_log(tmp / "room.log")
    log = read_carmen(log_path, max_usable_range=20.0)
    return log_path, write_bag(tmp / "room.bag", log.scans, log.timestamps)


def test_bag_datasets_run_like_the_log(room_bag, tmp_path):
    log_path, bag_path = room_bag
    spec = parse_spec(_bag_spec(log_path, bag_path, pose_topic="/odom"), "bags.toml")
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
    d = _bag_spec(log_path, bag_path)
    d["datasets"][1].update(entry)
    d["datasets"][1] = {k: v for k, v in d["datasets"][1].items() if v is not None}
    with pytest.raises(SpecError) as e:
        parse_spec(d, "bags.toml")
    assert str(e.value).startswith("bags.toml: ") and message in str(e.value), str(e.value)
    d = _bag_spec(log_path, log_path, pose_topic="/odom")
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


def test_unreachable_scheduler_fails_within_seconds(tmp_path):
    """A scheduler address nobody listens on: a ConnectionError naming it, within a few seconds."""
    import socket
    import time

    from ogm_ppl.experiment.runner import SCHEDULER_TIMEOUT_S

    with socket.socket() as s:  # a free port, closed again: nothing listens there
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    t0 = time.monotonic()
    with pytest.raises(ConnectionError, match=rf"127\.0\.0\.1:{port}"):
        run_experiment(parse_spec(tiny(), "tiny.toml"), tmp_path, scheduler=f"tcp://127.0.0.1:{port}", progress=False)
    assert time.monotonic() - t0 < SCHEDULER_TIMEOUT_S + 10


def test_beam_increment_in_degrees_is_the_multiple_of_the_logs(room_bag):
    from ogm_ppl.datasets import read_carmen

    log_path, bag_path = room_bag
    a = read_carmen(log_path, max_usable_range=20.0).scans.angles
    inc = float(np.degrees(np.diff(np.atleast_2d(a), axis=1)).mean())
    for kind_entry in ({}, {"pose_topic": "/odom"}):
        d = _bag_spec(log_path, bag_path, **kind_entry)
        if not kind_entry:
            d["datasets"] = d["datasets"][:1]
        for ds in d["datasets"]:
            ds["beam_increment_deg"] = [2 * inc, 4 * inc]
        spec = parse_spec(d, "inc.toml")
        assert sorted({ds.params["beam_step"] for ds in spec.datasets}) == [2, 4]
    d = _bag_spec(log_path, bag_path, pose_topic="/odom")
    d["datasets"] = d["datasets"][:1]
    d["datasets"][0]["beam_increment_deg"] = 2.5 * inc
    with pytest.raises(SpecError, match=r"beam_increment_deg: .* not a multiple of the scans' .*-degree increment"):
        parse_spec(d, "inc.toml")
    d["datasets"][0]["beam_step"] = 2
    with pytest.raises(SpecError, match="beam_step or beam_increment_deg, not both"):
        parse_spec(d, "inc.toml")


def test_a_prior_that_cannot_be_fingerprinted_warns():
    """A registered prior built for one grid size only cannot be fingerprinted on the 8 x 8 grid: no digest, and
    a warning that a change of that prior would not be noticed (a spec refuses such a name when it is read)."""
    from types import SimpleNamespace

    from ogm_ppl.priors import IndependentPrior, register_prior, unregister_prior

    def only_64(shape, tables):
        if tuple(shape) != (64, 64):
            raise RuntimeError(f"built for 64 x 64 grids, got {shape}")
        return IndependentPrior(0.3, 64 * 64)

    register_prior("test_only_64", only_64)
    try:
        alg = SimpleNamespace(name="gibbs-64", params={"prior": "test_only_64"})
        with pytest.warns(UserWarning, match="could not be built on an 8 x 8 grid"):
            assert T.algorithm_prior_digest(alg) is None
        assert T.algorithm_prior_digest(SimpleNamespace(name="ogm", params={"prior": 0.4})) is None
        assert len(T.algorithm_prior_digest(SimpleNamespace(name="g", params={"prior": "mrf:houseexpo"}))) == 16
    finally:
        unregister_prior("test_only_64")


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


def test_a_log_whose_grid_is_over_the_limit_is_refused(room_bag, tmp_path):
    """A log's grid is known only once the log is read: its base task refuses it, naming the log and the limit,
    before any map of it is allocated."""
    log_path, _ = room_bag
    d = _bag_spec(log_path, log_path)
    d["datasets"] = d["datasets"][:1]
    d["experiment"]["max_cells"] = 100
    with pytest.raises(ExperimentError) as e:
        run_experiment(parse_spec(d, "bags.toml"), tmp_path / "out", scheduler="serial", progress=False)
    assert f"{log_path}: the log's grid at 0.1 m a cell is " in str(e.value)
    assert "over the limit of 100 ([experiment] max_cells; or set the dataset's extent)" in str(e.value)
    assert not (tmp_path / "out" / "datasets" / "_base" / "log.npz").exists()


def _method_names():
    from ogm_ppl.methods import method_names

    return method_names()


@pytest.mark.parametrize("name", _method_names())
def test_the_warm_up_run_of_each_method_succeeds(name):
    """The untimed warm-up (numba compiling kept out of a task's seconds) runs each registered method with its
    default parameters cut down; a warm-up that raised would be skipped silently, so check none does."""
    from ogm_ppl.experiment.spec import AlgorithmSpec

    r = T.warm_run(AlgorithmSpec(name=name, kind=name, params={}), 1.0, 0.05)
    assert r.probabilities is not None and r.probabilities.shape == (24 * 24,)


def test_an_output_folder_of_another_experiment_is_refused(serial_run, tmp_path):
    """Running another experiment into a folder that holds one would mix their files (and overwrite the first's
    metrics): refused before any task, naming both; a file is no output folder. The same experiment reruns."""
    d = tiny()
    d["experiment"] = {**d.get("experiment", {}), "name": "other"}
    with pytest.raises(ValueError, match=r"holds the results of experiment 'smoke' \(its spec\.json\), not 'other'"):
        run_experiment(parse_spec(d, "tiny.toml"), serial_run.out_dir, scheduler="serial", progress=False)
    (tmp_path / "f").write_text("x")
    with pytest.raises(ValueError, match="exists and is not a folder"):
        run_experiment(parse_spec(d, "tiny.toml"), tmp_path / "f", scheduler="serial", progress=False)


def test_metrics_say_what_produced_them(serial_run):
    """``metrics.json`` carries the provenance block (command, commit, machine, date) and ``metrics.md`` ends
    with it."""
    out = serial_run.out_dir
    prov = json.loads((out / "metrics.json").read_text())["provenance"]
    assert {"command", "commit", "machine", "date", "ogm_ppl"} <= set(prov) and prov["machine"]["cores"] >= 1
    assert f"at commit {prov['commit']}" in (out / "metrics.md").read_text()


def test_a_long_run_task_prints_progress_lines_naming_it(serial_run, tmp_path, monkeypatch, capsys):
    """With progress on, a run task longer than 10 s (a clock that moves a second a call here) prints plain
    lines naming its dataset, algorithm and chain between the tasks' own lines; its numbers are unchanged."""
    import shutil

    out = tmp_path / "copy"
    shutil.copytree(serial_run.out_dir, out)
    spec = parse_spec(tiny(), "tiny.toml")
    for f in out.glob("tasks/office/gibbs-border-L9/c0/result.json"):
        f.unlink()
    clock = iter(range(10**7))
    monkeypatch.setattr("ogm_ppl.progress.time.perf_counter", lambda: float(next(clock)))
    r = run_experiment(spec, out, scheduler="serial", progress=True)
    assert r.executed == ["run/office/gibbs-border-L9/c0", "score/office/gibbs-border-L9"]
    err = capsys.readouterr().err.splitlines()
    mine = [line for line in err if line.startswith("office/gibbs-border-L9/c0: gibbs sweeps: ")]
    assert mine and mine[-1].endswith(", done")
    assert [line for line in err if line.startswith("tasks: ")]
    _same(_numbers(serial_run.out_dir), _numbers(out))


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


@pytest.mark.parametrize("scheduler", ["serial", None])
def test_a_failed_task_leaves_its_traceback_in_failures_txt(tmp_path, scheduler, capfd):
    """A task that raises: the error names ``failures.txt``, which holds its traceback (on dask too, where the
    workers' own "Compute Failed" reports are kept out of the log); a rerun with nothing failing removes it.
    The sensor is registered in this process only: dask's worker processes do not know it (as when its module
    is missing from $OGM_PPL_METHODS), and say so."""
    from ogm_ppl.sensors import GaussianRange, register_sensor, unregister_sensor

    state = {"fail": True}

    def flaky(sigma_cells, p_rand):
        if state["fail"]:
            raise ValueError("flaky sensor refuses today")
        return GaussianRange(sigma_cells, p_rand)

    register_sensor("test_flaky", flaky)
    try:
        d = tiny()
        d["algorithms"] = [d["algorithms"][0], {"name": "g", "kind": "gibbs", "sweeps": 2, "sensor": "test_flaky"}]
        d["output"] = {"maps": False, "figures": False}
        spec = parse_spec(d, "tiny.toml")
        with pytest.raises(ExperimentError) as e:
            run_experiment(spec, tmp_path, scheduler=scheduler, workers=1, progress=False)
        failures = tmp_path / "failures.txt"
        assert f"tracebacks in {failures}" in str(e.value)
        # the one run task (one dataset, one chain) and the score task that needed it
        assert "1 of " in str(e.value) and "tasks failed, and 1 that depend on them (first: run/" in str(e.value)
        text = failures.read_text()
        assert "Compute Failed" not in capfd.readouterr().err
        if scheduler is None:
            assert "unknown sensor kind 'test_flaky'" in text and "Traceback (most recent call last)" in text
            return
        assert "ValueError: flaky sensor refuses today" in text and 'in flaky\n    raise ValueError("flaky' in text
        state["fail"] = False
        run_experiment(spec, tmp_path, scheduler=scheduler, progress=False)
        assert not failures.exists()
    finally:
        unregister_sensor("test_flaky")


@pytest.mark.parametrize("path", sorted(SMOKE.parent.glob("*.toml")), ids=lambda p: p.name)
def test_every_shipped_spec_is_valid(path):
    """Each spec under experiments/specs reads and validates (a renamed parameter or a moved data file would
    otherwise surface only when someone runs it); a spec naming a guide that its docs train first into out/
    may lack only that file."""
    try:
        load_spec(path)
    except SpecError as e:
        assert "no such guide file: out/guides/" in str(e), str(e)


def test_ctrl_c_stops_a_dask_run_with_one_line_and_no_worker_tracebacks(tmp_path):
    """Ctrl-C reaches every process of the run (a terminal signals the whole process group): the driver stops
    and closes its cluster, the workers ignore it (no "KeyboardInterrupt" traceback from each), and a worker's
    heartbeat to the closed scheduler is kept out of the log; exit status 130."""
    import os
    import signal
    import subprocess
    import sys
    import time

    spec = SMOKE.read_text().replace("pose_fraction = [1.0, 0.5]", "pose_fraction = 1.0")
    spec = spec.replace('name = "smoke"', 'name = "long"', 1)
    spec += '\n[[algorithms]]\nname = "long"\nkind = "gibbs"\nsweeps = 200000\nchains = 2\n'
    path = tmp_path / "long.toml"
    path.write_text(spec)
    env = dict(os.environ, PYTHONPATH=str(SMOKE.parents[2]))
    p = subprocess.Popen(
        [sys.executable, "-m", "ogm_ppl", "experiment", str(path), "--workers", "2", "--out", str(tmp_path / "out")],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
        start_new_session=True,
    )
    try:
        deadline = time.monotonic() + 120
        while not list((tmp_path / "out").glob("tasks/*/long/c*/gibbs.npz")) and time.monotonic() < deadline:
            assert p.poll() is None, p.communicate()
            time.sleep(0.5)  # the long chains have started (their first checkpoint is written)
        os.killpg(p.pid, signal.SIGINT)
        _, err = p.communicate(timeout=120)
    finally:
        if p.poll() is None:
            os.killpg(p.pid, signal.SIGKILL)
    assert p.returncode == 130, err
    assert err.rstrip().endswith(
        f"ogm-ppl: interrupted; finished tasks and the samplers' checkpoints are kept in {tmp_path / 'out'}: the "
        "same command resumes from them"
    ), err
    assert "Traceback" not in err and "KeyboardInterrupt" not in err, err
