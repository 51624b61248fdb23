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


@pytest.fixture(scope="module")
def installed(dist, tmp_path_factory):
    """A fresh venv (no system site-packages) that held torch before the wheel was installed into it, with what
    ``pip list`` said before and after: ``(venv, before, after)``."""
    tmp_path = tmp_path_factory.mktemp("wheel")
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
    return venv, before, _installed(py)


def _outside_env() -> dict:
    """The environment of a user outside the source tree: no PYTHONPATH, the shared data named by
    ``$OGM_PPL_DATA`` (as a user of the wheel names it)."""
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV", "OGM_PPL_FLOORPLANS")}
    env.update(MPLBACKEND="Agg", PYTHONSAFEPATH="1", OGM_PPL_DATA=str(ROOT.parent / "shared" / "data"))
    return env


def test_wheel_keeps_torch_and_quick_start_runs(installed, tmp_path):
    venv, before, after = installed
    py = venv / "bin" / "python"
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
    env = _outside_env()
    out = _run(py, "-c", script, cwd=work, env=env)
    version = re.search(r"VERSION (\S+)", out).group(1)
    assert version == after["ogm-ppl"]
    assert _run(venv / "bin" / "ogm-ppl", "--version", cwd=work, env=env).strip() == f"ogm-ppl {version}"


ACTIVE_SPEC = """
[experiment]
kind = "active"
name = "tiny"

[plans]
corpus = "houseexpo"
count = 1
window = 40

[robot]
stops = 2
beams = 45
max_range_cells = 15
samples = 4
sweeps = 2

[[methods]]
name = "frontier"
rule = "frontier"

[[methods]]
name = "patch3-ig"
rule = "sample_info"
prior = "patch3:houseexpo"
"""


def test_the_workflows_run_from_the_installed_wheel(installed, tmp_path):
    """With no source tree: a prior fitted and a guide trained on plan files of one's own, priors and guides scored
    on them (``calibrate``, with its leakage checks), and an active-mapping spec; each writes what the docs say."""
    from tests._plan_folder import write_plan_folder

    venv = installed[0]
    ogm = venv / "bin" / "ogm-ppl"
    work = tmp_path / "work"
    work.mkdir()
    plans = write_plan_folder(work)
    env = _outside_env()

    _run(ogm, "fit-prior", "tables", "--plan-files", plans, "--pixel-size", "0.025", "--out", "tables", "--quiet",
         cwd=work, env=env)  # fmt: skip
    assert {p.name for p in (work / "tables").iterdir()} == {"prior_plans.npz", "prior_plans.json"}
    record = json.loads((work / "tables" / "prior_plans.json").read_text())
    assert record["provenance"]["command"].startswith("ogm-ppl fit-prior tables")

    guide = ["--examples", "4", "--val", "2", "--window", "40", "--channels", "4", "--dilations", "1", "2", "1"]
    _run(ogm, "train-guide", "--plan-files", plans, "--pixel-size", "0.025", *guide, "--steps", "2",
         "--out", "guide.npz", "--quiet", cwd=work, env=env)  # fmt: skip
    assert (work / "guide.npz").is_file() and (work / "guide.json").is_file()

    scene = ["--plans", "2", "--window", "36", "--poses", "2", "--beams", "45", "--range-cells", "30"]
    _run(ogm, "calibrate", "--plan-files", plans, "--pixel-size", "0.025", "--priors", "independent", "patch3",
         "--train", "houseexpo", *scene, "--sweeps", "4", "--burn", "2", "--no-figures", "--out", "cal",
         cwd=work, env=env)  # fmt: skip
    summary = json.loads((work / "cal" / "calibration_summary.json").read_text())
    assert {"independent:houseexpo", "patch3:houseexpo"} <= {r["prior_name"] for r in summary["summary"]}

    (work / "tiny.toml").write_text(ACTIVE_SPEC)
    _run(ogm, "experiment", "tiny.toml", "--scheduler", "serial", "--quiet", "--out", "active", cwd=work, env=env)
    assert (work / "active" / "metrics.json").is_file() and (work / "active" / "metrics.md").is_file()
