"""The experiment runner on the serial scheduler: outputs, resume, an interrupted chain, reruns of changed
priors, refused output folders, provenance and progress."""

import json

import numpy as np
import pytest

from ogm_ppl.experiment import parse_spec, run_experiment
from ogm_ppl.experiment import tasks as T
from tests.experiment._smoke import numbers, same, tiny


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
    same(numbers(serial_run.out_dir), numbers(out))
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
    same(numbers(serial_run.out_dir), numbers(out))


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
    same(numbers(serial_run.out_dir), numbers(out))
