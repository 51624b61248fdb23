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

Parts: ``mutate_modules.py`` (the modules and their tests), ``mutate_mutants.py`` (enumeration, sampling,
diffs), ``mutate_run.py`` (the copied tree, the numba cache per mutant, the forked child, the baseline),
``mutate_report.py`` (equivalents and the report), ``mutate_common.py`` (what they share); this file plans and drives.

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
import json
import sys
import time
from pathlib import Path

from mutate_common import (
    ANNOTATION,
    DETECTED,
    ERROR,
    INCOMPETENT,
    KILLED,
    ROOT,
    SURVIVED,
    TIMEOUT,
    atomic_write_text,
    sha,
)
from mutate_modules import MODULES
from mutate_mutants import (
    annotation_spans,
    changed_lines,
    compiles,
    enumerate_mutants,
    mutate_source,
    sample,
    unified_diff,
)
from mutate_report import current_results, equivalent_reason, load_equivalents, write_report
from mutate_run import PRELOAD, baselines, mutant_cache, numba_dependents, run_child, sync_tree, tail, test_deps


def build_plan(names: list[str], per_module: int | None, use_all: bool, seed: int):
    plan = []
    for name in names:
        m = MODULES[name]
        src = (ROOT / m.path).read_text()
        tests = [t for t in m.tests if (ROOT / t).exists()]
        # a result is kept while the module and its tests are unchanged (other modules may change:
        # the baseline, keyed on the whole package, then checks that the tests still pass)
        fp = sha(m.path, src, *[f.read_bytes() for t in tests for f in test_deps(ROOT, t)])
        population = enumerate_mutants(name, src)
        n = None if use_all else (per_module or m.sites)
        plan.append((name, m, src, tests, fp, sample(population, n, seed, name), len(population)))
    return plan


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
        write_report(out, current_results(results, plan), equivalents, plan)
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
            if earlier and earlier[-1]["outcome"] == ERROR and not compiles(mutate_source(src, mu), m.path):
                earlier[-1] = {**earlier[-1], "outcome": INCOMPETENT}  # recorded before that check existed
            if a.keep and earlier:
                record({**earlier[-1], "id": rid})
                continue
            if a.retest_survivors:
                # a mutant the old tests killed stays killed, and so does an equivalent survivor; any
                # other survivor runs again; one never run is left for a plain run
                if earlier and earlier[-1]["outcome"] == SURVIVED and equivalent_reason(earlier[-1], equivalents):
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
        write_report(out, current_results(results, plan), equivalents, plan)
        print(f"report: {out / 'report.md'}")
        return 0

    sync_tree(tree)
    for mod in PRELOAD:  # before any fork; ogm_ppl itself is only imported by the children
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
                if not compiles(mutated, m.path):
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
                    rec["log"] = tail(work / "log.txt", 12)
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
    write_report(out, current_results(results, plan), equivalents, plan)
    print(f"wall time {(time.monotonic() - t_start) / 60:.1f} min; report: {out / 'report.md'}")
    return 130 if interrupted else 0


if __name__ == "__main__":
    sys.exit(main())
