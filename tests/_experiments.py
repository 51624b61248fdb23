"""Run a script of ``experiments/`` in a fresh interpreter, as a user would: the tests of the thin scripts."""

import subprocess
import sys
from pathlib import Path

EXPERIMENTS = Path(__file__).resolve().parents[1] / "experiments"


def run_script(file: str, *args: object, cwd: Path | None = None) -> subprocess.CompletedProcess:
    """``python experiments/<file> ARGS`` (its output captured as text; the exit status not checked)."""
    cmd = [sys.executable, str(EXPERIMENTS / file), *map(str, args)]
    return subprocess.run(cmd, capture_output=True, text=True, cwd=cwd, check=False, timeout=900)
