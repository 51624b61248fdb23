"""Mutation testing of the core modules, ``make mutate``; not part of ``make test``.

Mutants are cosmic-ray's (its operators and its parso-based rewriting of the source file on disk; it
really changes the numba kernels, which mutmut 3 skips: it leaves decorated functions alone). This
script decides which mutants to run, where, and against which tests:

* **never the working tree.** The repository (without .git, the venv, out/ and caches) is copied to
  ``out/mutation/tree`` at every start; each mutant is written into that copy and put back after its
  run, so an interrupted run leaves the developer's tree untouched. The copy's package is the one
  imported: its root goes first on ``sys.path`` (the editable install's finder comes after path
  entries), and the baseline checks ``ogm_ppl.__file__``.
* **each module against the tests that cover it** (``MODULES`` below), in a forked child of one process
  that has already imported torch, Pyro, numba and pytest (never ``ogm_ppl``), with ``-x``: tests that
  killed earlier mutants of the module first, then the rest, fastest first. Tests slower than a
  module's ``max_test_s`` in the baseline are left out (the long MCMC runs of the Gibbs tests).
* **numba's cache.** Kernels are ``@njit(cache=True)``. Numba keys a cached function on the sha256 of
  its own source file only, so a mutant in one kernel file does reach that file's functions, but the
  cached machine code of kernels in *other* files that call it (``log_odds.py`` calls ``trace_ray`` of
  ``_raycast_kernels.py``; ``patch_state.py`` calls ``cells.py``; ``patches.py`` calls ``patch_rays.py``) still
  holds the unmutated callee, and the mutant would pass for a survivor. Each mutant therefore runs with
  its own ``NUMBA_CACHE_DIR``: a copy of the cache the baseline warmed, without the entries of the
  mutated file and of every numba module that imports it (transitively), which are compiled again.
* **sampling.** The cosmic-ray population over these modules is ~6,700 mutants (binary-operator swaps
  are half of them: every ``+`` becomes each of 11 other operators); at 5-40 s a mutant that is days.
  A run takes each module's ``sites`` (or ``--per-module``) code sites (a node some operator can
  change) at random, seeded, so a rerun picks the same ones (a smaller number picks a subset), with
  one random operator variant at each. ``--all`` runs every mutant. Not run: mutants of a numba
  decorator line (without ``@njit`` a kernel runs as Python, same numbers; ``cache=False`` compiles
  the same code), mutants that are not valid Python (*incompetent*), and mutants inside a type
  annotation of a module with ``from __future__ import annotations`` (never evaluated: equivalent).
* **outcomes.** *killed* (a test failed), *timeout* (2x the tests' baseline time + 45 s), *error* (the
  mutant breaks import or collection, or crashes the process: an out-of-bounds write in a kernel),
  *survived*; a survivor listed in ``tools/mutate_equivalents.toml`` with the reason it cannot change
  behaviour is *equivalent* and left out of the kill ratio, detected / (detected + survived).
* **results.** ``out/mutation/results.jsonl`` (one line per mutant run; a rerun resumes from it while
  the module's source and its test files are unchanged), ``summary.json`` (per module and in total),
  ``report.md`` and ``survivors/*.diff``. The baseline's per-test times are kept in ``baseline.json``.

Usage::

    python tools/mutate.py                       # every core module, its default number of sites
    python tools/mutate.py --modules metrics,sensors --per-module 40
    python tools/mutate.py --retest-survivors    # after adding tests: rerun the survivors, keep kills
    python tools/mutate.py --list                # the sampled mutants, without running them
    python tools/mutate.py --report-only         # rewrite report.md / summary.json from results
    python tools/mutate.py --fresh               # forget earlier results
"""

from __future__ import annotations

import argparse
import ast
import dataclasses
import difflib
import hashlib
import importlib.util
import json
import os
import random
import shutil
import signal
import sys
import time
from pathlib import Path

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10
    import tomli as tomllib  # type: ignore[no-redef]

ROOT = Path(__file__).resolve().parent.parent


def _load_atomic_write_text():
    """``ogm_ppl.io.atomic_write_text``, loaded from its file (standard library only) so that this process
    still never imports the ``ogm_ppl`` package (see the module docstring)."""
    spec = importlib.util.spec_from_file_location("_ogm_ppl_io", ROOT / "ogm_ppl" / "io.py")
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod.atomic_write_text


atomic_write_text = _load_atomic_write_text()


@dataclasses.dataclass(frozen=True)
class Module:
    path: str
    tests: tuple[str, ...]
    #: random sites (one mutant each) per run, unless ``--per-module`` says otherwise
    sites: int = 24
    #: tests slower than this in the baseline are left out (the long MCMC tests of the Gibbs kernels)
    max_test_s: float = 1e9


_GIBBS_TESTS = (
    "tests/inference/mcmc/test_gibbs.py",
    "tests/inference/mcmc/test_gibbs_priors.py",
    "tests/inference/mcmc/test_metropolis_cell.py",
    "tests/inference/mcmc/test_patch_python_sweep.py",
    "tests/inference/mcmc/test_resume_rng.py",
)

#: core module -> the test files that exercise it (read from their imports and call chains); a listed
#: file that does not exist yet is ignored
MODULES: dict[str, Module] = {
    "sensors": Module(
        "ogm_ppl/sensors.py",
        ("tests/test_sensors.py", "tests/test_sensor_contracts.py", "tests/test_range_convention.py"),
    ),
    "raycast": Module(
        "ogm_ppl/raycast.py",
        ("tests/test_raycast.py", "tests/test_range_convention.py"),
    ),
    "raycast_kernels": Module(
        "ogm_ppl/_raycast_kernels.py",
        ("tests/test_raycast.py", "tests/test_range_convention.py", "tests/inference/log_odds/test_log_odds.py"),
    ),
    "log_odds": Module(
        "ogm_ppl/inference/log_odds/maps.py",
        ("tests/inference/log_odds/test_log_odds.py",),
        sites=12,
    ),
    "log_odds_kernels": Module(
        "ogm_ppl/inference/_kernels/log_odds.py",
        ("tests/inference/log_odds/test_log_odds.py",),
        sites=12,
    ),
    "exact": Module(
        "ogm_ppl/inference/exact/posteriors.py",
        (
            "tests/inference/exact/test_exact.py",
            "tests/inference/exact/test_exact_input_checks.py",
            "tests/inference/exact/test_pose_constrained_evidence.py",
            "tests/test_posterior.py",
        ),
        sites=12,
        max_test_s=5,
    ),
    "posterior": Module(
        "ogm_ppl/posterior.py",
        ("tests/inference/exact/test_exact.py", "tests/test_posterior.py"),
        sites=12,
        max_test_s=5,
    ),
    "metrics": Module("ogm_ppl/metrics.py", ("tests/test_metrics.py",), sites=16),
    "cells_kernels": Module(
        "ogm_ppl/inference/_kernels/cells.py",
        ("tests/inference/exact/test_map_estimate.py", "tests/inference/patch_map/test_patch_map.py", *_GIBBS_TESTS),
        sites=6,
        max_test_s=5,
    ),
    "patch_state_kernels": Module(
        "ogm_ppl/inference/_kernels/patch_state.py",
        ("tests/inference/patch_map/test_patch_map.py", *_GIBBS_TESTS),
        sites=1,
        max_test_s=5,
    ),
    "patch_rays_kernels": Module(
        "ogm_ppl/inference/_kernels/patch_rays.py",
        ("tests/inference/patch_map/test_patch_map.py", *_GIBBS_TESTS),
        sites=2,
        max_test_s=5,
    ),
    "patch_lik_kernels": Module(
        "ogm_ppl/inference/_kernels/patch_lik.py",
        ("tests/inference/patch_map/test_patch_map.py", *_GIBBS_TESTS),
        sites=2,
        max_test_s=5,
    ),
    "additive_sweep_kernels": Module(
        "ogm_ppl/inference/_kernels/additive_sweep.py",
        ("tests/inference/patch_map/test_patch_map.py", *_GIBBS_TESTS),
        sites=1,
        max_test_s=5,
    ),
    "candidate_sweep_kernels": Module(
        "ogm_ppl/inference/_kernels/candidate_sweep.py",
        ("tests/inference/patch_map/test_patch_map.py", *_GIBBS_TESTS),
        sites=2,
        max_test_s=5,
    ),
    "patch_sweep_kernels": Module(
        "ogm_ppl/inference/_kernels/patch_sweep.py",
        ("tests/inference/patch_map/test_patch_map.py", *_GIBBS_TESTS),
        sites=1,
        max_test_s=5,
    ),
    "patches_kernels": Module(
        "ogm_ppl/inference/_kernels/patches.py",
        ("tests/inference/patch_map/test_patch_map.py", "tests/inference/patch_map/test_patch_map_weights.py"),
        sites=6,
        max_test_s=5,
    ),
    "runner": Module(
        "ogm_ppl/inference/mcmc/runner.py",
        ("tests/inference/mcmc/test_checkpoint.py", "tests/inference/mcmc/test_running_stats.py", *_GIBBS_TESTS),
        sites=8,
        max_test_s=5,
    ),
}

#: imported before forking, so that each mutant's child starts in ~1 s instead of ~6 s; never ogm_ppl
_PRELOAD = (
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

#: see ``baselines``
RECHECK_S = 5.0

KILLED, TIMEOUT, ERROR, SURVIVED = "killed", "timeout", "error", "survived"
INCOMPETENT = "incompetent"  # not valid Python (``x & not y``): not run, left out of every count
ANNOTATION = "annotation"  # inside a type annotation: equivalent, not run (see ``annotation_spans``)
_ANNOTATION_REASON = (
    "inside a type annotation, which `from __future__ import annotations` keeps as an unevaluated string"
)
DETECTED = (KILLED, TIMEOUT, ERROR)


def _sha(*parts: bytes | str) -> str:
    h = hashlib.sha256()
    for p in parts:
        h.update(p.encode() if isinstance(p, str) else p)
    return h.hexdigest()[:16]


# ------------------------------------------------------------------------------------------- mutants


@dataclasses.dataclass
class Mutant:
    module: str
    operator: str
    occurrence: int
    line: int
    site: tuple[int, int, int, int]

    @property
    def key(self) -> str:
        return f"{self.module}:{self.operator}:{self.occurrence}"


def _operators():
    import cosmic_ray.plugins

    for name in sorted(cosmic_ray.plugins.operator_names()):
        cls = cosmic_ray.plugins.get_operator(name)
        if not cls.arguments():  # the variable replacer/inserter need arguments: not used
            yield name, cls()


def enumerate_mutants(name: str, source: str) -> list[Mutant]:
    """Every cosmic-ray mutant of one module (as ``cosmic-ray init`` finds them)."""
    from cosmic_ray.ast import ast_nodes, get_ast

    lines = source.splitlines()
    nodes = list(ast_nodes(get_ast(source)))
    out = []
    for op_name, op in _operators():
        positions = [(s, e) for node in nodes for s, e in op.mutation_positions(node)]
        for occ, (start, end) in enumerate(positions):
            text = lines[start[0] - 1]
            if "pragma: no mutate" in text:
                continue
            if text.lstrip().startswith(("@nb.", "@numba.", "@njit", "@jit")):
                # numba's decorator: without it the kernel runs as Python (same numbers, only slower);
                # cache=False or a changed inline option compile the same code
                continue
            out.append(Mutant(name, op_name, occ, start[0], (*start, *end)))
    return out


def sample(mutants: list[Mutant], per_module: int | None, seed: int, name: str) -> list[Mutant]:
    """``per_module`` random sites, one random operator variant at each (all mutants when ``None``)."""
    if per_module is None:
        return list(mutants)
    rng = random.Random(f"{seed}:{name}")
    by_site: dict[tuple, list[Mutant]] = {}
    for m in mutants:
        by_site.setdefault(m.site, []).append(m)
    sites = sorted(by_site)
    rng.shuffle(sites)
    chosen = [rng.choice(by_site[s]) for s in sites[:per_module]]
    return sorted(chosen, key=lambda m: (m.line, m.operator, m.occurrence))


def annotation_spans(source: str) -> list[tuple[tuple[int, int], tuple[int, int]]]:
    """``(start, end)`` positions of the type annotations of a module that has ``from __future__ import
    annotations`` (there they are strings, never evaluated: a mutant inside one is equivalent)."""
    if "from __future__ import annotations" not in source:
        return []
    spans = []
    for n in ast.walk(ast.parse(source)):
        anns = []
        if isinstance(n, ast.arg) and n.annotation is not None:
            anns.append(n.annotation)
        elif isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef)) and n.returns is not None:
            anns.append(n.returns)
        elif isinstance(n, ast.AnnAssign):
            anns.append(n.annotation)
        spans += [((a.lineno, a.col_offset), (a.end_lineno or a.lineno, a.end_col_offset or 0)) for a in anns]
    return spans


def _compiles(source: str | None, path: str) -> bool:
    try:
        compile(source or "", path, "exec")
    except SyntaxError:
        return False
    return True


def mutate_source(source: str, m: Mutant) -> str | None:
    import cosmic_ray.plugins
    from cosmic_ray.mutating import mutate_code

    return mutate_code(source, cosmic_ray.plugins.get_operator(m.operator)(), m.occurrence)


def changed_lines(original: str, mutated: str) -> tuple[str, str]:
    a, b = original.splitlines(), mutated.splitlines()
    old, new = [], []
    for tag, i1, i2, j1, j2 in difflib.SequenceMatcher(a=a, b=b, autojunk=False).get_opcodes():
        if tag != "equal":
            old += [s.strip() for s in a[i1:i2]]
            new += [s.strip() for s in b[j1:j2]]
    return " / ".join(old), " / ".join(new)


def unified_diff(original: str, mutated: str, path: str) -> str:
    return "".join(
        difflib.unified_diff(original.splitlines(True), mutated.splitlines(True), f"a/{path}", f"b/{path}", n=3)
    )


# -------------------------------------------------------------------------------- the copied tree


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


def _test_deps(tree: Path, test: str) -> list[Path]:
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
    files = [*pkg, *sorted(tree.glob("tests/**/conftest.py")), tree / "pyproject.toml", *_test_deps(tree, test)]
    return _sha(*[str(f.relative_to(tree)).encode() + f.read_bytes() for f in files])


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


def _tail(path: Path, n: int = 25) -> str:
    try:
        return "".join(path.read_text(errors="replace").splitlines(True)[-n:])
    except OSError:
        return ""


# ------------------------------------------------------------------------------------------ driver


def load_equivalents() -> list[dict]:
    p = ROOT / "tools" / "mutate_equivalents.toml"
    if not p.exists():
        return []
    return tomllib.loads(p.read_text()).get("equivalent", [])


def _equivalent_reason(r: dict, equivalents: list[dict]) -> str | None:
    for e in equivalents:
        if e["module"] == r["module"] and e["line"] == r["original"] and e["mutant"] == r["mutated"]:
            return e["reason"]
    return None


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
    print("   " + (_tail(work / "baseline.txt", 10**6).splitlines() or ["?"])[0], flush=True)
    if rc != 0:
        print(
            f"baseline failed (rc {rc}): the tests must pass on the unmutated code first\n"
            f"{_tail(work / 'baseline.txt')}"
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


def build_plan(names: list[str], per_module: int | None, use_all: bool, seed: int):
    plan = []
    for name in names:
        m = MODULES[name]
        src = (ROOT / m.path).read_text()
        tests = [t for t in m.tests if (ROOT / t).exists()]
        # a result is kept while the module and its tests are unchanged (other modules may change:
        # the baseline, keyed on the whole package, then checks that the tests still pass)
        fp = _sha(m.path, src, *[f.read_bytes() for t in tests for f in _test_deps(ROOT, t)])
        population = enumerate_mutants(name, src)
        n = None if use_all else (per_module or m.sites)
        plan.append((name, m, src, tests, fp, sample(population, n, seed, name), len(population)))
    return plan


def _current(results: dict[str, dict], plan) -> dict[str, dict]:
    """For each planned mutant its latest result (a survivor retested under new tests supersedes the
    old result)."""
    cur = {}
    for _name, _m, _src, _tests, _fp, muts, _n in plan:
        for mu in muts:
            cands = [r for r in results.values() if r["id"].startswith(mu.key + ":")]
            if cands:
                cur[mu.key] = cands[-1]
    return cur


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--modules", default="", help="comma-separated names (default: all): " + ", ".join(MODULES))
    ap.add_argument(
        "--per-module", type=int, default=None, help="random sites per module (default: each module's own, 6-24)"
    )
    ap.add_argument("--all", action="store_true", help="every mutant, no sampling (days)")
    ap.add_argument("--seed", type=int, default=15)
    ap.add_argument("--out", default=str(ROOT / "out" / "mutation"))
    ap.add_argument("--fresh", action="store_true", help="forget earlier results")
    ap.add_argument(
        "--retest-survivors",
        action="store_true",
        help="after the tests changed: rerun earlier survivors only, keep the kills",
    )
    ap.add_argument(
        "--keep", action="store_true", help="resume and keep earlier results even where the tests changed since"
    )
    ap.add_argument("--report-only", action="store_true", help="rewrite the report from results.jsonl")
    ap.add_argument("--list", action="store_true", help="print the sampled mutants and stop")
    a = ap.parse_args(argv)

    names = [n.strip() for n in a.modules.replace(" ", ",").split(",") if n.strip()] or list(MODULES)
    unknown = [n for n in names if n not in MODULES]
    if unknown:
        ap.error(f"unknown module(s) {unknown}; known: {', '.join(MODULES)}")
    t_start = time.monotonic()
    out = Path(a.out).resolve()
    tree, results_path, work = out / "tree", out / "results.jsonl", out / "work"
    work.mkdir(parents=True, exist_ok=True)
    if a.fresh:
        results_path.unlink(missing_ok=True)
    results: dict[str, dict] = {}
    if results_path.exists():
        for line in results_path.read_text().splitlines():
            r = json.loads(line)
            results[r["id"]] = r
    equivalents = load_equivalents()
    plan = build_plan(names, a.per_module, a.all, a.seed)
    if a.report_only:
        write_report(out, _current(results, plan), equivalents, plan)
        print(f"report: {out / 'report.md'}")
        return 0
    if a.list:
        for name, _m, src, _t, _fp, muts, n_all in plan:
            print(f"{name}: {len(muts)} of {n_all} mutants")
            for mu in muts:
                mutated = mutate_source(src, mu)
                o, n = changed_lines(src, mutated) if mutated else ("?", "?")
                print(f"  L{mu.line:<4} {mu.operator.split('/')[-1]:<40} {o}  ->  {n}")
        return 0

    def record(rec: dict) -> None:
        results[rec["id"]] = rec
        with results_path.open("a") as fh:
            fh.write(json.dumps(rec) + "\n")

    todo_by_module = {}
    for name, m, src, _tests, fp, muts, _n in plan:
        todo = []
        for mu in muts:
            rid = f"{mu.key}:{fp}"
            if rid in results:
                continue
            earlier = [r for r in results.values() if r["id"].startswith(mu.key + ":")]
            if earlier and earlier[-1]["outcome"] == ERROR and not _compiles(mutate_source(src, mu), m.path):
                earlier[-1] = {**earlier[-1], "outcome": INCOMPETENT}  # recorded before that check existed
            if a.keep and earlier:
                record({**earlier[-1], "id": rid})
                continue
            if a.retest_survivors:
                # a mutant the old tests killed stays killed, and so does an equivalent survivor; any
                # other survivor runs again; one never run is left for a plain run
                if earlier and earlier[-1]["outcome"] == SURVIVED and _equivalent_reason(earlier[-1], equivalents):
                    record({**earlier[-1], "id": rid})
                    continue
                if earlier and earlier[-1]["outcome"] != SURVIVED:
                    record({**earlier[-1], "id": rid})
                if not earlier or earlier[-1]["outcome"] != SURVIVED:
                    continue
            todo.append(mu)
        todo_by_module[name] = todo
    total = sum(len(t) for t in todo_by_module.values())
    print(
        f"{total} mutants to run in {out / 'tree'} "
        f"({sum(len(p[5]) for p in plan) - total} results kept from earlier runs)",
        flush=True,
    )
    if not total:
        write_report(out, _current(results, plan), equivalents, plan)
        print(f"report: {out / 'report.md'}")
        return 0

    sync_tree(tree)
    for mod in _PRELOAD:  # before any fork; ogm_ppl itself is only imported by the children
        __import__(mod)
    base_cache = out / "numba-cache" / "base"
    files = sorted({t for name, _m, _s, tests, *_ in plan if todo_by_module[name] for t in tests})
    durations_by_file = baselines(tree, files, base_cache, work, out / "baseline.json")
    if durations_by_file is None:
        return 2

    done_n = 0
    interrupted = False
    try:
        for name, m, src, tests, fp, muts, n_all in plan:
            todo = todo_by_module[name]
            if not todo:
                continue
            durations = {i: d for t in tests for i, d in durations_by_file[t].items()}
            ids = [i for i, d in durations.items() if d <= m.max_test_s]
            budget = sum(durations[i] for i in ids)
            timeout = 2 * budget + 45
            n_slow = len(durations) - len(ids)
            left_out = f" ({n_slow} slower than {m.max_test_s:g} s left out)" if n_slow else ""
            print(
                f"== {name} ({m.path}): {len(todo)} of {len(muts)} sampled mutants to run "
                f"(population {n_all}); {len(ids)} tests, {budget:.0f} s"
                f"{left_out}",
                flush=True,
            )
            kills: dict[str, int] = {}
            for r in results.values():
                if r["module"] == name and r.get("killer"):
                    kills[r["killer"]] = kills.get(r["killer"], 0) + 1
            stale = numba_dependents(tree, m.path)
            annotations = annotation_spans(src)
            target = tree / m.path
            for mu in todo:
                done_n += 1
                mutated = mutate_source(src, mu)
                if mutated is None:
                    continue
                rec = {
                    "id": f"{mu.key}:{fp}",
                    "module": name,
                    "path": m.path,
                    "operator": mu.operator,
                    "occurrence": mu.occurrence,
                    "line": mu.line,
                }
                rec["original"], rec["mutated"] = changed_lines(src, mutated)
                rec["diff"] = unified_diff(src, mutated, m.path)
                if any(a <= mu.site[:2] < b for a, b in annotations):
                    record({**rec, "outcome": ANNOTATION, "seconds": 0.0})
                    print(
                        f"[{done_n}/{total}] {name} L{mu.line} {mu.operator.split('/')[-1]}: "
                        "in a type annotation (equivalent, not run)",
                        flush=True,
                    )
                    continue
                if not _compiles(mutated, m.path):
                    record({**rec, "outcome": INCOMPETENT, "seconds": 0.0})
                    print(
                        f"[{done_n}/{total}] {name} L{mu.line} {mu.operator.split('/')[-1]}: "
                        f"{INCOMPETENT} (not valid Python)",
                        flush=True,
                    )
                    continue
                ordered = sorted(ids, key=lambda i: (-kills.get(i, 0), durations[i]))
                cache = work / "numba-cache"
                mutant_cache(base_cache, cache, stale)
                atomic_write_text(target, mutated)
                try:
                    rc, dt = run_child(tree, ["-x", *ordered], cache, work / "log.txt", work / "rec.json", timeout)
                finally:
                    atomic_write_text(target, src)
                rep = json.loads((work / "rec.json").read_text()) if (work / "rec.json").exists() else {}
                if rc is None:
                    rec["outcome"] = TIMEOUT
                elif rc == 0:
                    rec["outcome"] = SURVIVED
                elif rc == 1 and rep.get("failed"):
                    rec["outcome"] = KILLED
                    rec["killer"] = rep["failed"][0]
                    kills[rec["killer"]] = kills.get(rec["killer"], 0) + 1
                else:  # import / collection error, or a crash of the child: the mutant is detected
                    rec["outcome"] = ERROR
                    rec["log"] = _tail(work / "log.txt", 12)
                rec["seconds"] = round(dt, 1)
                record(rec)
                mod_rs = [r for r in results.values() if r["module"] == name and r["id"].endswith(fp)]
                k = sum(r["outcome"] in DETECTED for r in mod_rs)
                el = time.monotonic() - t_start
                print(
                    f"[{done_n}/{total} {el / 60:5.1f} min] {name} L{mu.line} "
                    f"{mu.operator.split('/')[-1]}: {rec['outcome']}"
                    f"{' by ' + rec['killer'] if rec.get('killer') else ''} ({dt:.1f} s)"
                    f"  | {name}: {k}/{len(mod_rs)} detected",
                    flush=True,
                )
    except KeyboardInterrupt:
        interrupted = True
        print("interrupted: the results so far are kept; run again to resume", flush=True)
    finally:
        for _name, m, src, *_ in plan:  # the copy is put back whatever happened
            atomic_write_text(tree / m.path, src)
    write_report(out, _current(results, plan), equivalents, plan)
    print(f"wall time {(time.monotonic() - t_start) / 60:.1f} min; report: {out / 'report.md'}")
    return 130 if interrupted else 0


def write_report(out: Path, results: dict[str, dict], equivalents: list[dict], plan) -> None:
    """``report.md``, ``summary.json`` and ``survivors/*.diff`` for the planned mutants' results."""
    surv_dir = out / "survivors"
    if surv_dir.exists():
        shutil.rmtree(surv_dir)
    surv_dir.mkdir(parents=True)
    summary: dict[str, dict] = {}
    rows, surv_md, eq_md = [], [], []
    counted = (KILLED, TIMEOUT, ERROR, SURVIVED, "equivalent")
    for name, m, _src, tests, _fp, muts, n_all in plan:
        rs = sorted((r for r in results.values() if r["module"] == name), key=lambda r: (r["line"], r["operator"]))
        if not rs:
            continue
        c = {k: 0 for k in (*counted, INCOMPETENT)}
        for i, r in enumerate(rs):
            outcome = r["outcome"]
            reason = _equivalent_reason(r, equivalents) if outcome == SURVIVED else None
            if outcome == ANNOTATION:
                reason = _ANNOTATION_REASON
            if reason:
                outcome = "equivalent"
            c[outcome] += 1
            if r["outcome"] not in (SURVIVED, ANNOTATION):
                continue
            fn = f"{name}-L{r['line']}-{r['operator'].split('/')[-1]}-{i}.diff"
            atomic_write_text(surv_dir / fn, r.get("diff", ""))
            item = (
                f"* `{name}` line {r['line']}, {r['operator'].split('/')[-1]}: "
                f"`{r['original']}` -> `{r['mutated']}` ([diff](survivors/{fn}))"
            )
            (eq_md.append(f"{item}\n  {reason}") if reason else surv_md.append(item))
        det = c[KILLED] + c[TIMEOUT] + c[ERROR]
        denom = det + c[SURVIVED]
        summary[name] = {
            "path": m.path,
            "population": n_all,
            "sampled": len(muts),
            "run": len(rs),
            **c,
            "kill_ratio": round(det / denom, 4) if denom else None,
            "tests": tests,
        }
        ratio = f"{det / denom:.0%}" if denom else "-"
        rows.append(
            f"| {name} | {n_all} | {len(rs)} | {c[KILLED]} | {c[TIMEOUT]} | {c[ERROR]} | "
            f"{c[SURVIVED]} | {c['equivalent']} | {c[INCOMPETENT]} | {ratio} |"
        )
    tot = {k: sum(v[k] for v in summary.values()) for k in ("population", "run", *counted, INCOMPETENT)}
    det = tot[KILLED] + tot[TIMEOUT] + tot[ERROR]
    denom = det + tot[SURVIVED]
    summary["total"] = {**tot, "kill_ratio": round(det / denom, 4) if denom else None}
    atomic_write_text(out / "summary.json", json.dumps(summary, indent=2) + "\n")
    md = [
        "# Mutation testing (`make mutate`, tools/mutate.py)",
        "",
        "cosmic-ray mutants of the core modules, a random sample of code sites per module (one "
        "operator variant each), each run against the tests that cover its module. *Detected* = killed "
        "(a test failed) + timeout + error (the mutant breaks import or collection). *Equivalent*: a "
        "survivor listed with its reason in `tools/mutate_equivalents.toml`. *Incompetent*: not valid "
        "Python, not run. Kill ratio = detected / (detected + survived).",
        "",
        "| module | population | run | killed | timeout | error | survived | equivalent | incompetent | kill ratio |",
        "|---|---|---|---|---|---|---|---|---|---|",
        *rows,
        f"| **total** | {tot['population']} | {tot['run']} | {tot[KILLED]} | {tot[TIMEOUT]} | "
        f"{tot[ERROR]} | {tot[SURVIVED]} | {tot['equivalent']} | {tot[INCOMPETENT]} | "
        f"{f'{det / denom:.0%}' if denom else '-'} |",
        "",
        "## Survivors",
        "",
        *(surv_md or ["none"]),
        "",
        "## Equivalent survivors",
        "",
        *(eq_md or ["none"]),
        "",
    ]
    atomic_write_text(out / "report.md", "\n".join(md))


if __name__ == "__main__":
    sys.exit(main())
