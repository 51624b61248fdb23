"""The ``active`` experiment kind: the small spec through the CLI, resume, the outputs, spec errors, leakage."""

import json
import shutil
from pathlib import Path

import pytest

from ogm_ppl.experiment import SpecError, load_spec, parse_spec
from ogm_ppl.experiment.active import ActiveSpec

SPECS = Path(__file__).resolve().parents[2] / "experiments" / "specs"


def _tiny(**over) -> dict:
    d = {
        "experiment": {"kind": "active", "name": "tiny", "seed": 1},
        "plans": {"corpus": "houseexpo", "count": 1, "window": 40, "seeds": [0]},
        "robot": {"stops": 3, "beams": 40, "max_range_cells": 12, "samples": 4, "sweeps": 1},
        "methods": [
            {"name": "frontier", "rule": "frontier"},
            {"name": "ind", "rule": "sample_info", "prior": "independent"},
        ],
        "output": {"figures": False},
    }
    for k, v in over.items():
        d[k] = {**d[k], **v} if isinstance(v, dict) else v
    return d


def test_both_specs_parse():
    for name in ("active_small.toml", "active.toml"):
        s = load_spec(SPECS / name)
        assert isinstance(s, ActiveSpec) and s.kind == "active"
    full = load_spec(SPECS / "active.toml")
    assert full.count >= 10 and len(full.seeds) >= 2 and full.window <= 200
    rules = {m["rule"] for m in full.methods}
    assert rules == {"frontier", "ogm_info", "sample_info", "sample_coverage"}
    assert any(m.get("prior", "").partition(":")[2] for m in full.methods)  # a learned prior


def test_the_small_spec_runs_through_the_cli_and_resumes(tmp_path):
    from ogm_ppl.cli import main

    out = tmp_path / "out"
    assert (
        main(["experiment", str(SPECS / "active_small.toml"), "--out", str(out), "--scheduler", "serial", "--quiet"])
        == 0
    )
    spec = load_spec(SPECS / "active_small.toml")
    doc = json.loads((out / "metrics.json").read_text())
    n = spec.count * len(spec.seeds) * len(spec.methods)
    assert len(doc["runs"]) == n and not doc["failed"]
    assert [r["method"] for r in doc["summary"]] == [m["name"] for m in spec.methods]
    # the path to best F1 0.8 (and coverage 0.8) is summarised beside the 0.9 levels, from the per-stop records
    assert all({"path_to_f1_0.8", "reached_f1_0.8", "ratio_coverage_0.8"} <= set(r) for r in doc["summary"])
    assert all(set(r["path_levels"]) == {"coverage", "f1", "coverage_0.8", "f1_0.8"} for r in doc["runs"])
    assert all(r["path_levels"]["f1_0.8"] <= r["path_levels"]["f1"] for r in doc["runs"])
    assert (out / "figures" / "active_curves.png").stat().st_size > 1000
    assert "path to 90 % cov." in (out / "metrics.md").read_text()
    task = json.loads(next((out / "tasks").rglob("s0.json")).read_text())
    recs = task["records"]
    assert 1 <= len(recs) <= spec.stops and recs[0]["path_length"] == 0.0
    assert all(k in recs[-1] for k in ("coverage", "f1", "nll_bits", "path_length", "f1_ogm", "nll_ogm"))
    # the methods of one (plan, seed) start at the same cell
    starts = {json.dumps(json.loads(p.read_text())["start"]) for p in (out / "tasks" / "p00").rglob("s0.json")}
    assert len(starts) == 1
    from ogm_ppl.experiment import run_experiment

    again = run_experiment(SPECS / "active_small.toml", out, scheduler="serial", progress=False)
    assert not again.executed and len(again.skipped) == n
    assert [r["final"] for r in again.runs] == [r["final"] for r in doc["runs"]]


def test_spec_errors_name_the_table_and_key():
    with pytest.raises(SpecError, match=r"robot\.speed: unknown key"):
        parse_spec(_tiny(robot={"speed": 1.0}), "t.toml")
    with pytest.raises(SpecError, match=r"methods\[1\] \('ind'\)\.prior: unknown prior"):
        parse_spec(
            _tiny(methods=[{"name": "f", "rule": "frontier"}, {"name": "ind", "rule": "sample_info", "prior": "nope"}]),
            "t.toml",
        )
    with pytest.raises(SpecError, match=r"methods\[0\] \('x'\)\.rule: must be one of"):
        parse_spec(_tiny(methods=[{"name": "x", "rule": "random"}]), "t.toml")
    with pytest.raises(SpecError, match=r"plans\.seeds"):
        parse_spec(_tiny(plans={"seeds": []}), "t.toml")
    with pytest.raises(SpecError, match=r"robot: Robot\.threshold"):
        parse_spec(_tiny(robot={"threshold": 1.5}), "t.toml")
    with pytest.raises(SpecError, match=r"datasets: unknown table"):
        parse_spec({**_tiny(), "datasets": []}, "t.toml")
    with pytest.raises(SpecError, match=r"experiment\.kind: must be one of"):
        parse_spec({"experiment": {"kind": "explore"}, "datasets": [], "algorithms": []}, "t.toml")


def test_a_learned_prior_is_refused_on_a_plan_it_was_trained_on(tmp_path, monkeypatch):
    from ogm_ppl.calibration import LeakageError, heldout_maps, leakage
    from ogm_ppl.experiment import active

    spec = parse_spec(_tiny(methods=[{"name": "p", "rule": "sample_info", "prior": "patch3:houseexpo"}]), "t.toml")
    plan = heldout_maps("houseexpo", 1, 40)[0].plan
    monkeypatch.setattr(leakage, "training_set", lambda corpus: {plan})
    with pytest.raises(LeakageError, match="training set"):
        active.run_active(spec, tmp_path, scheduler="serial", progress=False)
    assert not (tmp_path / "tasks").exists()  # refused before anything ran
    shutil.rmtree(tmp_path)


def test_only_keeps_the_named_methods_in_the_spec_order():
    spec = load_spec(SPECS / "active.toml")
    sub = spec.only(["patch3-cov-per-m", "frontier"])
    assert [m["name"] for m in sub.methods] == ["frontier", "patch3-cov-per-m"]
    assert sub.robot == spec.robot and sub.seeds == spec.seeds
    with pytest.raises(SpecError, match="no method 'nearest' in the spec"):
        spec.only(["nearest"])
