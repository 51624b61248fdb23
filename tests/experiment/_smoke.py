"""The smoke spec cut down for the tests of :mod:`ogm_ppl.experiment`, and what two runs' outputs are compared by."""

import json
import tomllib
from pathlib import Path

import numpy as np

SMOKE = Path(__file__).resolve().parents[2] / "experiments" / "specs" / "smoke.toml"


def tiny(**output) -> dict:
    """The smoke spec cut down for tests: one dataset, OGM and a 2-chain border-prior Gibbs run."""
    d = tomllib.loads(SMOKE.read_text())
    d["datasets"][0]["pose_fraction"] = 1.0
    d["algorithms"] = [d["algorithms"][0], d["algorithms"][1]]
    d["output"] = {"maps": False, "figures": False, **output}
    return d


def numbers(out: Path) -> dict:
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


def same(a: dict, b: dict) -> None:
    assert a["scores"] == b["scores"] and a["pooled"] == b["pooled"]
    assert a["runs"] == b["runs"] and a["traces"] == b["traces"]
    assert a["maps"].keys() == b["maps"].keys()
    for k in a["maps"]:
        assert np.array_equal(a["maps"][k], b["maps"][k]), k


def bag_spec(log_path: Path, bag_path: Path, **bag_entry) -> dict:
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
