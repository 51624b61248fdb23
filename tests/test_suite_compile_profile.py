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
