"""tools/suite_compile_profile.py's report: per test file the sums of its tests' seconds, CPU seconds and compile
seconds, costliest first; per compiled function its compilations, distinct signatures and own seconds."""

import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def test_report_sums_tests_into_files_and_signatures_into_functions(tmp_path):
    profile = {
        "wall": {"tests/a.py::x": 1.0, "tests/a.py::y": 2.5, "tests/b.py::z": 9.0},
        "cpu": {"tests/a.py::x": 0.5, "tests/a.py::y": 1.0, "tests/b.py::z": 4.0},
        "compile_wall": {"tests/a.py::y": 2.0},
        "compile_cpu": {"tests/a.py::y": 0.7},
        "compiled": [
            {"function": "ogm_ppl.k:sweep", "args": "(int64,)", "exclusive": 1.5, "inclusive": 2.0, "test": "t"},
            {"function": "ogm_ppl.k:sweep", "args": "(float64,)", "exclusive": 0.2, "inclusive": 0.2, "test": "t"},
            {"function": "numba.np:impl", "args": "(int64,)", "exclusive": 5.0, "inclusive": 5.0, "test": "t"},
        ],
    }
    path = tmp_path / "p.json"
    path.write_text(json.dumps(profile))
    cmd = [sys.executable, str(ROOT / "tools" / "suite_compile_profile.py"), str(path)]
    lines = subprocess.run(cmd, capture_output=True, text=True, check=True).stdout.splitlines()
    assert lines[1].split() == ["9.0", "0.0", "4.0", "0.0", "tests/b.py"]  # the costlier file first
    assert lines[2].split() == ["3.5", "2.0", "1.5", "0.7", "tests/a.py"]
    assert lines[3].split() == ["12.5", "2.0", "5.5", "0.7", "all", "2", "files"]
    assert [ln.split() for ln in lines[6:]] == [["2", "2", "1.7", "ogm_ppl.k:sweep"]]  # numba's own left out


def test_report_gives_each_xdist_workers_finishing_time_after_the_earliest_start(tmp_path):
    """Profiles written by pytest-xdist workers carry the worker's name and its session's start and end (epoch
    seconds): the report lists the workers by finishing time, counted from the earliest start of all of them."""
    paths = []
    for worker, start, end, seconds in (("gw0", 100.0, 400.0, 250.0), ("gw1", 101.0, 250.5, 120.0)):
        profile = {
            "wall": {f"tests/{worker}.py::t": seconds},
            "cpu": {},
            "compile_wall": {},
            "compile_cpu": {},
            "compiled": [],
            "worker": worker,
            "clock": {"start": start, "end": end},
        }
        paths.append(tmp_path / f"p.{worker}.json")
        paths[-1].write_text(json.dumps(profile))
    cmd = [sys.executable, str(ROOT / "tools" / "suite_compile_profile.py"), *map(str, paths)]
    lines = subprocess.run(cmd, capture_output=True, text=True, check=True).stdout.splitlines()
    at = next(i for i, ln in enumerate(lines) if ln.split()[:1] == ["finished"])
    assert [ln.split() for ln in lines[at + 1 :]] == [["150.5", "120.0", "gw1"], ["300.0", "250.0", "gw0"]]
