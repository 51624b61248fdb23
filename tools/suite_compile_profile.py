"""Where a cold test run spends its time: a pytest plugin that records each test's seconds and CPU seconds and the
numba compilation inside it, and a report of the costliest test files and compiled functions.

    make clean-numba
    CI=1 PYTHONPATH=tools SUITE_PROFILE_OUT=out/profile/inference.json \\
        .venv/bin/python -m pytest -p no:cacheprovider -p suite_compile_profile -n 0 tests/inference
    python tools/suite_compile_profile.py out/profile/*.json [--top N]

    # the whole suite as `make test` runs it: one profile per worker, out/profile/suite.gw0.json, ...gw1.json
    CI=1 PYTHONPATH=tools SUITE_PROFILE_OUT=out/profile/suite.json .venv/bin/python -m pytest -p no:cacheprovider \
        -p suite_compile_profile -n 2 --dist loadfile -m "not packaging" tests

The plugin listens to numba's ``numba:compile`` events (:mod:`numba.core.event`): every specialisation compiled
from scratch (not loaded from the disk cache), with its argument types, its own seconds (``exclusive``: less the
functions it compiled inside it) and the test that triggered it; a test's compile seconds are those of the
outermost compilations. Under pytest-xdist (``-n 2 --dist loadfile``, as ``make test`` runs) each worker writes
its own file (``SUITE_PROFILE_OUT`` with ``.gw0``, ``.gw1``... before the suffix) and the report also gives each
worker's test seconds and when it finished (seconds since the earliest start over all the profiles): the skew
between the workers is what a whole-file split costs. Wall seconds on a shared machine follow its load; CPU seconds
(``time.process_time``, all threads of the process) much less.
"""

from __future__ import annotations

import argparse
import collections
import json
import os
import time
from pathlib import Path

_state: dict = {"test": "<collection>", "stack": []}
_wall: dict[str, float] = collections.defaultdict(float)
_cpu: dict[str, float] = collections.defaultdict(float)
_compile_wall: dict[str, float] = collections.defaultdict(float)
_compile_cpu: dict[str, float] = collections.defaultdict(float)
_compiled: list[dict] = []
_clock: dict[str, float] = {}  # session start and end (epoch seconds)


def _listen() -> None:
    from numba.core import event

    class Compiles(event.Listener):
        def on_start(self, ev):
            d = ev.data
            _state["stack"].append([time.perf_counter(), time.process_time(), 0.0, d["dispatcher"], d["args"]])

        def on_end(self, ev):
            t0, c0, inner, dispatcher, args = _state["stack"].pop()
            wall = time.perf_counter() - t0
            if _state["stack"]:
                _state["stack"][-1][2] += wall
            else:
                _compile_wall[_state["test"]] += wall
                _compile_cpu[_state["test"]] += time.process_time() - c0
            f = dispatcher.py_func
            _compiled.append(
                {
                    "function": f"{f.__module__}:{f.__qualname__}",
                    "args": str(args),
                    "exclusive": wall - inner,
                    "inclusive": wall,
                    "test": _state["test"],
                }
            )

    event.register("numba:compile", Compiles())


def pytest_configure(config) -> None:
    _listen()
    _clock["start"] = time.time()


def pytest_runtest_logstart(nodeid, location) -> None:
    _state["test"] = nodeid
    _cpu[nodeid] -= time.process_time()  # the test's CPU seconds: end minus start (pytest_runtest_logfinish)


def pytest_runtest_logfinish(nodeid, location) -> None:
    _cpu[nodeid] += time.process_time()
    _state["test"] = "<between tests>"


def pytest_runtest_logreport(report) -> None:
    _wall[report.nodeid] += report.duration


def pytest_sessionfinish(session) -> None:
    out = os.environ.get("SUITE_PROFILE_OUT")
    worker = os.environ.get("PYTEST_XDIST_WORKER")
    controller = not worker and getattr(session.config.option, "numprocesses", None)  # its workers write
    if out and not controller:
        path = Path(out)
        if worker:
            path = path.with_name(f"{path.stem}.{worker}{path.suffix}")
        path.parent.mkdir(parents=True, exist_ok=True)
        _clock["end"] = time.time()
        payload = {
            "wall": _wall,
            "cpu": _cpu,
            "compile_wall": _compile_wall,
            "compile_cpu": _compile_cpu,
            "compiled": _compiled,
            "worker": worker or "main",
            "clock": _clock,
        }
        path.write_text(json.dumps(payload))


def report(paths: list[Path], top: int) -> str:
    """The costliest test files (seconds, CPU seconds, their compile share) and compiled functions (how many
    specialisations, their own seconds) over the profiles ``paths``."""
    per_file = collections.defaultdict(lambda: [0.0, 0.0, 0.0, 0.0])
    per_function = collections.defaultdict(lambda: [0, 0.0, set()])
    workers = []
    for p in paths:
        d = json.loads(p.read_text())
        if "clock" in d:
            workers.append((d["worker"], d["clock"]["start"], d["clock"]["end"], sum(d["wall"].values())))
        for i, key in enumerate(("wall", "cpu", "compile_wall", "compile_cpu")):
            for test, s in d[key].items():
                per_file[test.split("::")[0]][i] += s
        for c in d["compiled"]:
            if c["function"].startswith(("ogm_ppl", "tests")):
                f = per_function[c["function"]]
                f[0] += 1
                f[1] += c["exclusive"]
                f[2].add(c["args"])
    lines = [f"{'seconds':>8} {'compile':>8} {'cpu s':>8} {'compile':>8}  test file"]
    for name, (w, c, cw, cc) in sorted(per_file.items(), key=lambda kv: -kv[1][0])[:top]:
        lines.append(f"{w:8.1f} {cw:8.1f} {c:8.1f} {cc:8.1f}  {name}")
    total = [sum(v[i] for v in per_file.values()) for i in range(4)]
    lines.append(f"{total[0]:8.1f} {total[2]:8.1f} {total[1]:8.1f} {total[3]:8.1f}  all {len(per_file)} files")
    lines += ["", f"{'compiles':>8} {'distinct':>8} {'seconds':>8}  compiled function (its own seconds)"]
    for name, (n, s, sigs) in sorted(per_function.items(), key=lambda kv: -kv[1][1])[:top]:
        lines.append(f"{n:8d} {len(sigs):8d} {s:8.1f}  {name}")
    if workers:
        t0 = min(w[1] for w in workers)
        lines += ["", f"{'finished':>8} {'tests s':>8}  worker (finished: seconds after the earliest start)"]
        for name, _, end, tests in sorted(workers, key=lambda w: w[2]):
            lines.append(f"{end - t0:8.1f} {tests:8.1f}  {name}")
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("profiles", nargs="+", type=Path)
    ap.add_argument("--top", type=int, default=20)
    args = ap.parse_args()
    print(report(args.profiles, args.top))


if __name__ == "__main__":
    main()
