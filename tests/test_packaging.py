"""The built wheel and sdist are complete: installed into a fresh venv that already holds torch, the wheel
keeps that torch, and the README's quick start runs from the installed wheel (not this source tree), so
the package data (``ogm_ppl/fitted/*.json``, ``*.npz``) is proven to ship.

Slow-ish (a venv, the local torch wheel, the dependencies from pip's cache): marked ``packaging``;
``pytest -m "not packaging"`` skips it.
"""

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
CONSTRAINTS = ROOT / "constraints.txt"

pytestmark = pytest.mark.packaging


def _run(*cmd, cwd=None, env=None):
    res = subprocess.run([str(c) for c in cmd], cwd=cwd, env=env, capture_output=True, text=True)
    assert res.returncode == 0, f"{' '.join(map(str, cmd))} failed:\n{res.stdout[-3000:]}\n{res.stderr[-3000:]}"
    return res.stdout


def _installed(py):
    out = _run(py, "-m", "pip", "list", "--format=json", "--disable-pip-version-check")
    return {p["name"].lower().replace("_", "-"): p["version"] for p in json.loads(out)}


@pytest.fixture(scope="module")
def dist(tmp_path_factory):
    out = tmp_path_factory.mktemp("dist")
    # sdist first, then the wheel built *from the sdist*: proves the sdist is complete as well
    _run(sys.executable, "-m", "build", "--outdir", out, ROOT)
    wheels, sdists = list(out.glob("*.whl")), list(out.glob("*.tar.gz"))
    assert len(wheels) == 1 and len(sdists) == 1, sorted(p.name for p in out.iterdir())
    return wheels[0]


def test_wheel_ships_package_data(dist):
    import zipfile

    names = zipfile.ZipFile(dist).namelist()
    for pattern in (r"ogm_ppl/fitted/.+\.json$", r"ogm_ppl/fitted/.+\.npz$", r"ogm_ppl/_raycast_kernels\.py$"):
        assert any(re.match(pattern, n) for n in names), pattern
    assert not any(n.startswith("tests/") for n in names)


def test_wheel_keeps_torch_and_quick_start_runs(dist, tmp_path):
    venv = tmp_path / "venv"
    _run(sys.executable, "-m", "venv", venv)  # no system site-packages: only what we install
    py = venv / "bin" / "python"
    # a researcher's environment: torch is already there (here the local CPU wheel of our pin)
    _run(py, "-m", "pip", "install", "-q", "-c", CONSTRAINTS, "torch")
    before = _installed(py)
    assert "torch" in before

    # pip's resolver: installing the wheel would change no installed package (torch included)
    report = tmp_path / "report.json"
    _run(py, "-m", "pip", "install", "-q", "--dry-run", "--report", report, "-c", CONSTRAINTS, dist)
    would_install = {
        i["metadata"]["name"].lower().replace("_", "-"): i["metadata"]["version"]
        for i in json.loads(report.read_text())["install"]
    }
    assert "ogm-ppl" in would_install
    changed = {n: (before[n], v) for n, v in would_install.items() if n in before}
    assert not changed, f"the wheel would change installed packages: {changed}"

    _run(py, "-m", "pip", "install", "-q", "-c", CONSTRAINTS, dist)
    after = _installed(py)
    assert after["torch"] == before["torch"]
    assert all(after.get(n) == v for n, v in before.items())

    # the README's first Python block, from outside the source tree, against the installed wheel
    work = tmp_path / "work"
    work.mkdir()
    block = re.findall(r"```python\n(.*?)```", (ROOT / "README.md").read_text(), flags=re.S)[0]
    script = (
        "import ogm_ppl, pathlib, sys\n"
        "assert 'site-packages' in ogm_ppl.__file__, ogm_ppl.__file__\n"
        f"assert not pathlib.Path(ogm_ppl.__file__).is_relative_to({str(ROOT)!r})\n"
        "fitted = pathlib.Path(ogm_ppl.__file__).parent / 'fitted'\n"
        "assert list(fitted.glob('*.json')) and list(fitted.glob('*.npz'))\n"
        + block
        + "\nprint('VERSION', ogm_ppl.__version__)\n"
    )
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV")}
    env.update(MPLBACKEND="Agg", PYTHONSAFEPATH="1")
    out = _run(py, "-c", script, cwd=work, env=env)
    version = re.search(r"VERSION (\S+)", out).group(1)
    assert version == after["ogm-ppl"]
    assert _run(venv / "bin" / "ogm-ppl", "--version", cwd=work, env=env).strip() == f"ogm-ppl {version}"
