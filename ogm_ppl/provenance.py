"""What produced a result: the command line, the git commit of the code and the machine.

Every JSON the library's experiments and benchmarks write carries this block under ``"provenance"``, and the
docs' tables print it under each table (``tools/gen_docs_tables.py``).

>>> p = provenance("python -m ogm_ppl experiment smoke.toml")
>>> sorted(p), sorted(p["machine"])[:3]
(['command', 'commit', 'date', 'machine', 'ogm_ppl'], ['cores', 'cpu', 'numba'])
"""

from __future__ import annotations

import datetime
import os
import platform
import shlex
import subprocess
import sys
from pathlib import Path

__all__ = ["provenance", "command_line"]

#: the checkout the package was imported from (a git work tree for an editable install)
ROOT = Path(__file__).resolve().parent.parent


def _cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def _git_commit(root: Path) -> str:
    """``git rev-parse HEAD`` of ``root``, with ``-dirty`` when tracked files of the code that produces
    results (``ogm_ppl/``, ``benchmarks/``, ``experiments/``) differ from it; edits to docs do not count.
    ``"unknown"`` outside a git checkout (an installed wheel)."""
    if not (root / ".git").exists():
        return "unknown"
    try:
        head = subprocess.run(
            ["git", "rev-parse", "HEAD"], cwd=root, capture_output=True, text=True, check=True
        ).stdout.strip()
        dirty = subprocess.run(
            ["git", "status", "--porcelain", "--untracked-files=no", "--", "ogm_ppl", "benchmarks", "experiments"],
            cwd=root,
            capture_output=True,
            text=True,
            check=True,
        ).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"
    return head + ("-dirty" if dirty else "")


def command_line() -> str:
    """This process's command line as a user would type it: ``python -m ogm_ppl ...`` for the module,
    ``ogm-ppl ...`` for the console script, ``python SCRIPT ...`` (relative to the checkout) for a script."""
    argv0 = Path(sys.argv[0]) if sys.argv and sys.argv[0] else Path("python")
    args = sys.argv[1:]
    if argv0.name == "__main__.py" and argv0.parent.name == "ogm_ppl":
        return shlex.join(["python", "-m", "ogm_ppl", *args])
    if argv0.name in ("ogm-ppl", "ogm_ppl"):
        return shlex.join(["ogm-ppl", *args])
    script = argv0.resolve()
    try:
        name = str(script.relative_to(ROOT))
    except ValueError:
        name = str(argv0)
    return shlex.join(["python", name, *args])


def provenance(command: str | None = None) -> dict:
    """``command`` (default :func:`command_line`), the git ``commit`` of the checkout the package came from,
    the ``ogm_ppl`` version, the ``machine`` (CPU, cores, Python, torch, numba, numpy, platform) and the UTC
    ``date``. Versions are those of the imported packages: the ones that ran, not the ones pinned."""
    from importlib.metadata import PackageNotFoundError, version

    import numba
    import numpy
    import torch

    try:
        own = version("ogm_ppl")
    except PackageNotFoundError:
        own = "unknown"
    return {
        "command": command_line() if command is None else command,
        "commit": _git_commit(ROOT),
        "ogm_ppl": own,
        "machine": {
            "cpu": _cpu_model(),
            "cores": os.cpu_count(),
            "python": platform.python_version(),
            "torch": torch.__version__,
            "numba": numba.__version__,
            "numpy": numpy.__version__,
            "platform": platform.platform(),
        },
        "date": datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ"),
    }
