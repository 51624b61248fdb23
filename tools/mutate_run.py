"""How ``tools/mutate.py`` runs a mutant: the copied tree, each test file's dependencies, the numba cache
without the mutated file's dependents, the forked pytest child, and the baseline of the unmutated copy."""

from __future__ import annotations

import ast
import json
import os
import shutil
import signal
import sys
import time
from pathlib import Path

from mutate_common import RECHECK_S, ROOT, atomic_write_text, sha

#: imported before forking, so that each mutant's child starts in ~1 s instead of ~6 s; never ogm_ppl
PRELOAD = (
    "numpy",
    "scipy.special",
    "scipy.stats",
    "torch",
    "pyro",
    "pyro.distributions",
    "pyro.infer",
    "numba",
    "pytest",
    "hypothesis",
    "tqdm",
)


def sync_tree(tree: Path) -> None:
    """A fresh copy of the repository (tests read files from experiments/ and docs/), without git,
    the virtualenv, outputs and caches."""
    skip = {
        ".git",
        ".venv",
        "out",
        "build",
        "dist",
        ".hypothesis",
        ".mypy_cache",
        ".pytest_cache",
        ".ruff_cache",
        "__pycache__",
        "_build",
    }
    ignore = shutil.ignore_patterns(*skip, "*.pyc", "*.egg-info")
    if tree.exists():
        shutil.rmtree(tree)
    tree.mkdir(parents=True)
    for entry in ROOT.iterdir():
        if entry.name in skip or entry.name.endswith(".egg-info"):
            continue
        if entry.is_dir():
            shutil.copytree(entry, tree / entry.name, ignore=ignore, symlinks=True)
        else:
            shutil.copy2(entry, tree / entry.name)


def test_deps(tree: Path, test: str) -> list[Path]:
    """A test file and the test modules it imports (``from .x.test_y import helper``), transitively."""
    seen: list[Path] = []
    todo = [tree / test]
    while todo:
        f = todo.pop()
        if f in seen or not f.exists():
            continue
        seen.append(f)
        for node in ast.walk(ast.parse(f.read_text())):
            if isinstance(node, ast.ImportFrom) and node.level:
                base = f.parent
                for _ in range(node.level - 1):
                    base = base.parent
                mod = base.joinpath(*(node.module or "").split("."))
                todo += [mod.with_suffix(".py"), mod / "__init__.py"]
                todo += [mod / f"{n.name}.py" for n in node.names]
    return seen


def test_file_key(tree: Path, test: str) -> str:
    """Changes when the package, the conftest, the test file or a test module it imports changes."""
    pkg = sorted((tree / "ogm_ppl").rglob("*.py"))
    files = [*pkg, *sorted(tree.glob("tests/**/conftest.py")), tree / "pyproject.toml", *test_deps(tree, test)]
    return sha(*[str(f.relative_to(tree)).encode() + f.read_bytes() for f in files])


def _module_of(path: Path, pkg_root: Path) -> str:
    rel = path.relative_to(pkg_root.parent).with_suffix("")
    parts = rel.parts[:-1] if rel.name == "__init__" else rel.parts
    return ".".join(parts)


def numba_dependents(tree: Path, target: str) -> set[Path]:
    """``target`` and every numba module that imports it, directly or through other numba modules or
    package ``__init__`` re-exports: the files whose cached kernels can embed the target's code."""
    pkg = tree / "ogm_ppl"
    files = {_module_of(p, pkg): p for p in pkg.rglob("*.py")}
    is_numba = {m: "numba" in p.read_text() for m, p in files.items()}
    importers: dict[str, set[str]] = {}
    for mod, p in files.items():
        for node in ast.walk(ast.parse(p.read_text())):
            if isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("ogm_ppl"):
                importers.setdefault(node.module, set()).add(mod)
    start = _module_of(tree / target, pkg)
    seen, todo = {start}, [start]
    while todo:
        for imp in importers.get(todo.pop(), ()):
            if imp not in seen and (is_numba[imp] or files[imp].name == "__init__.py"):
                seen.add(imp)
                todo.append(imp)
    return {files[m] for m in seen if is_numba[m]}


def mutant_cache(base: Path, dest: Path, stale: set[Path]) -> None:
    """``dest``: a copy of the warmed numba cache ``base`` without the entries of the ``stale`` files."""
    from numba.core.caching import _CacheLocator

    if dest.exists():
        shutil.rmtree(dest)
    shutil.copytree(base, dest) if base.exists() else dest.mkdir(parents=True)
    for f in stale:
        sub = dest / _CacheLocator.get_suitable_cache_subpath(str(f))
        for entry in sub.glob(f"{f.stem}.*"):
            entry.unlink()


# ----------------------------------------------------------------------------------- running tests


class _Recorder:
    """pytest plugin of the child: each test's outcome and duration, written as JSON at the end."""

    def __init__(self, path: Path):
        self.path, self.tests, self.failed = path, {}, []

    def pytest_runtest_logreport(self, report):
        d = self.tests.setdefault(report.nodeid, 0.0)
        self.tests[report.nodeid] = d + report.duration
        if report.failed and report.nodeid not in self.failed:
            self.failed.append(report.nodeid)

    def pytest_collection_modifyitems(self, items):
        self.collected = [it.nodeid for it in items]

    def pytest_sessionfinish(self, session):
        atomic_write_text(
            self.path,
            json.dumps({"tests": self.tests, "failed": self.failed, "collected": getattr(self, "collected", [])}),
        )


def run_child(
    tree: Path, args: list[str], cache_dir: Path, log: Path, rec: Path, timeout: float, check_import: bool = False
) -> tuple[int | None, float]:
    """pytest ``args`` in a forked child (its own process group) inside ``tree``; ``None`` on timeout.
    ``check_import``: first check that the copy's ``ogm_ppl``, not the working tree's, is imported."""
    rec.unlink(missing_ok=True)
    t0 = time.monotonic()
    pid = os.fork()
    if pid == 0:  # child
        rc = 3
        try:
            os.setpgid(0, 0)
            fd = os.open(log, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
            os.dup2(fd, 1)
            os.dup2(fd, 2)
            os.chdir(tree)
            sys.path.insert(0, str(tree))
            os.environ["NUMBA_CACHE_DIR"] = str(cache_dir)
            os.environ["CI"] = "1"  # the hypothesis "ci" profile: derandomised, as `make test`
            import numba.core.config

            numba.core.config.CACHE_DIR = str(cache_dir)
            if check_import:
                import ogm_ppl

                print("ogm_ppl imported from", ogm_ppl.__file__, flush=True)
                if not ogm_ppl.__file__.startswith(str(tree) + os.sep):
                    raise RuntimeError(f"imported {ogm_ppl.__file__}, not the copy in {tree}")
            if not args:  # the import check alone
                os._exit(0)
            import pytest

            rc = int(pytest.main(["-q", "-p", "no:cacheprovider", "-o", "addopts=", *args], plugins=[_Recorder(rec)]))
        except BaseException:
            import traceback

            traceback.print_exc()
        finally:
            sys.stdout.flush()
            sys.stderr.flush()
            os._exit(rc)
    try:
        while True:
            done, status = os.waitpid(pid, os.WNOHANG)
            if done:
                return os.waitstatus_to_exitcode(status), time.monotonic() - t0
            if time.monotonic() - t0 > timeout:
                break
            time.sleep(0.05)
    finally:  # on a timeout, and on Ctrl-C: the child and whatever it started go too
        try:
            os.killpg(pid, signal.SIGKILL)
            os.waitpid(pid, 0)
        except (ProcessLookupError, ChildProcessError):
            pass
    return None, time.monotonic() - t0


def tail(path: Path, n: int = 25) -> str:
    try:
        return "".join(path.read_text(errors="replace").splitlines(True)[-n:])
    except OSError:
        return ""


def baselines(tree: Path, files: list[str], base_cache: Path, work: Path, store: Path) -> dict | None:
    """Every test of ``files`` on the unmutated copy, which must pass; returns ``{file: {nodeid:
    seconds}}``. Kept in ``store`` per test file (keyed on ``test_file_key``), so that a rerun only
    runs the files that changed; the run also warms the numba cache ``base_cache``."""
    known = json.loads(store.read_text()) if store.exists() and base_cache.exists() else {}
    keys = {f: test_file_key(tree, f) for f in files}
    missing = [f for f in files if known.get(f, {}).get("key") != keys[f]]
    # a file measured before (when the package differed) is rechecked without its tests slower than
    # RECHECK_S: those keep their old durations (no module runs them against mutants at that size)
    slow = [i for f in missing for i, d in known.get(f, {}).get("tests", {}).items() if d > RECHECK_S]
    print(
        f"baseline: {', '.join(missing) or 'all kept from an earlier run'}"
        f"{f' ({len(slow)} slow tests not rerun)' if slow else ''}",
        flush=True,
    )
    args = [*missing, *(a for i in slow for a in ("--deselect", i))] if missing else []
    # the import check always runs: the copy's package, not the working tree's, must be imported
    rc, dt = run_child(tree, args, base_cache, work / "baseline.txt", work / "baseline.json", 3600, check_import=True)
    print("   " + (tail(work / "baseline.txt", 10**6).splitlines() or ["?"])[0], flush=True)
    if rc != 0:
        print(
            f"baseline failed (rc {rc}): the tests must pass on the unmutated code first\n{tail(work / 'baseline.txt')}"
        )
        return None
    if missing:
        rep = json.loads((work / "baseline.json").read_text())
        for f in missing:
            tests = {i: d for i, d in rep["tests"].items() if i.split("::")[0] == f}
            tests.update({i: d for i, d in known.get(f, {}).get("tests", {}).items() if i in slow})
            known[f] = {"key": keys[f], "tests": tests}
        print(f"   {len(rep['tests'])} tests pass ({dt:.0f} s)", flush=True)
        atomic_write_text(store, json.dumps(known, indent=1))
    return {f: known[f]["tests"] for f in files}
