r"""The ``active`` experiment kind: active mapping in simulation (:mod:`ogm_ppl.exploration.active`) on held-out
plans, every plan x seed x method one task, on dask like the map experiments.

A spec with ``[experiment] kind = "active"`` (read by :func:`ogm_ppl.experiment.load_spec`, run by
``ogm-ppl experiment SPEC --out DIR``) has these tables (defaults in brackets)::

    [experiment]   kind = "active", name [file stem], seed [0], description [""]
    [plans]        corpus ["houseexpo"; a floor-plan corpus, or "generated"], count [2], window [64] (cells:
                   each plan cropped to the window holding the most wall-side cells,
                   :func:`~ogm_ppl.calibration.heldout_maps`), seeds [[0]] (start, range noise and chain)
    [robot]        the fields of ogm_ppl.exploration.active.Robot, and stops [10], stop_coverage [1.0]
    [[methods]]    name (*required*), rule (*required*: "frontier", "ogm_info", "sample_info",
                   "sample_coverage"), prior (rules sample_info, sample_coverage: a prior name), per_metre
                   [false], distance_offset [the max range, metres], estimator ["beam" | "scan"], scan_draws
                   [64], patch [the prior's tile; [r, c] or 1]
    [output]       figures [true], dpi [100]

Plans are the held-out plans of the corpus (:func:`~ogm_ppl.datasets.floorplans.heldout_plans`, real-log
buildings left out) or held-out generated maps, as the calibration experiment chooses them, and every learned
prior is checked against them before anything runs: :func:`~ogm_ppl.calibration.check_heldout`
rebuilds each shipped table's training set from its provenance and refuses a plan in it or of the same building.

Outputs under ``--out``: ``plans/pNN.npz`` (truth), ``tasks/pNN/METHOD/sSEED.json`` (per-stop records, the
route, path length to 90 % coverage and to F1 0.9, seconds), ``metrics.json`` (every task's summary and the
per-method summary), ``metrics.md`` (the table: path length to 90 % coverage and to F1 0.9, median over runs
that reach it and how many do, paired ratio to the first method, wall seconds per run) and
``figures/active_curves.png`` (coverage, best F1 and NLL against path length: the median over plans and seeds
and the 25-75 % band; a run's last value holds after its last stop).
"""

from __future__ import annotations

import json
import math
import os
import time
from dataclasses import asdict, dataclass, field, fields, replace
from pathlib import Path

import numpy as np

from ogm_ppl.calibration import check_heldout, heldout_maps
from ogm_ppl.experiment.spec_tables import SpecError, Table, check_name, derive_seed, named_entry
from ogm_ppl.io import atomic_write_text
from ogm_ppl.provenance import provenance

__all__ = ["ActiveResult", "ActiveSpec", "parse_active_spec", "run_active", "run_active_task", "summarise"]

LEVELS = {"coverage": 0.9, "f1": 0.9}  # the path length needed to reach these
MORE_LEVELS = (("coverage", 0.8), ("f1", 0.8))  # also summarised (keys ..._0.8), from the per-stop records
_TABLES = ("experiment", "plans", "robot", "methods", "output")


@dataclass(frozen=True)
class ActiveSpec:
    """A validated ``active`` spec (module docstring)."""

    name: str
    seed: int
    description: str
    corpus: str
    count: int
    window: int
    seeds: tuple
    robot: dict
    stops: int
    stop_coverage: float
    methods: tuple  # of dicts: the fields of exploration.active.Method
    figures: bool = True
    dpi: int = 100
    source: str = "<dict>"
    kind: str = "active"

    def only(self, methods) -> ActiveSpec:
        """The same spec with only the named methods (in the spec's order; ``--algorithms`` of the command
        line): run a subset now, the rest later into the same output folder (a rerun resumes every task
        already done). Raises :class:`SpecError` naming an unknown method."""
        names = list(dict.fromkeys(methods))
        known = [m["name"] for m in self.methods]
        unknown = [n for n in names if n not in known]
        if unknown:
            raise SpecError(f"{self.source}: no method {unknown[0]!r} in the spec; it has {', '.join(known)}")
        return replace(self, methods=tuple(m for m in self.methods if m["name"] in names))

    def to_json(self) -> dict:
        return asdict(self)


# ------------------------------------------------------------------------------------------ spec
def parse_active_spec(data: dict, source: str = "<dict>", base_dir: str | os.PathLike = ".") -> ActiveSpec:
    """Validate an ``active`` spec given as a dict; errors name the file, the table and the key."""
    from ogm_ppl.exploration.active import RULES, Method, Robot

    unknown = sorted(set(data) - set(_TABLES))
    if unknown:
        raise SpecError(f"{source}: {unknown[0]}: unknown table (known in an active spec: {', '.join(_TABLES)})")
    e = Table(source, "experiment", data.get("experiment", {}))
    e.get("kind", "str", required=True, choices=("active",))
    stem = Path(source).stem if source != "<dict>" else "active"
    name = e.get("name", "str", stem)
    check_name(e, name)
    seed = e.get("seed", "int", 0, lo=0)
    description = e.raw("description", "")
    if not isinstance(description, str):
        e.fail("description", "must be a string")
    e.finish()

    p = Table(source, "plans", data.get("plans", {}))
    from ogm_ppl.datasets.floorplans import CORPORA

    corpus = p.get("corpus", "str", "houseexpo", choices=("generated",) + CORPORA)
    count = p.get("count", "int", 2, lo=1)
    window = p.get("window", "int", 64, lo=16)
    seeds = p.raw("seeds", [0])
    ok = isinstance(seeds, list) and seeds and all(isinstance(s, int) and not isinstance(s, bool) for s in seeds)
    if not ok or min(seeds) < 0:
        p.fail("seeds", f"must be a non-empty list of integers >= 0, got {seeds!r}")
    if len(set(seeds)) != len(seeds):
        p.fail("seeds", f"lists a seed twice: {seeds!r}")
    p.finish()

    r = Table(source, "robot", data.get("robot", {}))
    robot: dict = {}
    for f in fields(Robot):
        if not r.has(f.name):
            continue
        kind = {int: "int", float: "float", str: "str"}[type(f.default)]
        robot[f.name] = r.get(f.name, kind)
    stops = r.get("stops", "int", 10, lo=1)
    stop_coverage = r.get("stop_coverage", "float", 1.0, lo=0, lo_open=True, hi=1)
    r.finish()
    try:
        Robot(**robot)
    except ValueError as err:
        raise SpecError(f"{source}: robot: {err}") from None

    raw = data.get("methods")
    if not isinstance(raw, list) or not raw:
        raise SpecError(f"{source}: methods: at least one [[methods]] entry is required")
    methods = []
    for i, m in enumerate(raw):
        t, mname = named_entry(source, "methods", i, m)
        d = {"name": mname, "rule": t.get("rule", "str", required=True, choices=RULES)}
        if t.has("prior"):
            d["prior"] = t.get("prior", "str")
        d["per_metre"] = t.get("per_metre", "bool", False)
        if t.has("distance_offset"):
            d["distance_offset"] = t.get("distance_offset", "float", lo=0, lo_open=True)
        d["estimator"] = t.get("estimator", "str", "beam", choices=("beam", "scan"))
        d["scan_draws"] = t.get("scan_draws", "int", 64, lo=1)
        if t.has("patch"):
            pv = t.raw("patch")
            if pv == 1:
                pv = [1, 1]
            if not (isinstance(pv, list) and len(pv) == 2 and all(isinstance(x, int) and x >= 1 for x in pv)):
                t.fail("patch", f"must be [rows, cols] or 1, got {pv!r}")
            d["patch"] = tuple(pv)
        t.finish()
        try:
            Method(**d)
        except ValueError as err:
            t.fail("rule", str(err))
        if "prior" in d:
            from ogm_ppl.priors.named import prior_by_name

            try:
                prior_by_name(d["prior"], (4, 4))
            except (ValueError, KeyError, FileNotFoundError) as err:
                t.fail("prior", f"unknown prior ({err})")
        methods.append(d)
    names = [m["name"] for m in methods]
    dup = next((n for n in names if names.count(n) > 1), None)
    if dup:
        raise SpecError(f"{source}: methods: the name {dup!r} is used twice")
    o = Table(source, "output", data.get("output", {}))
    figures = o.get("figures", "bool", True)
    dpi = o.get("dpi", "int", 100, lo=20, hi=600)
    o.finish()
    return ActiveSpec(
        name, seed, description, corpus, count, window, tuple(seeds), robot, stops, stop_coverage,
        tuple(methods), figures, dpi, source,
    )  # fmt: skip


# ------------------------------------------------------------------------------------------ tasks
def _plan_path(out: Path, pid: str) -> Path:
    return Path(out) / "plans" / f"{pid}.npz"


def task_path(out: Path, pid: str, method: str, seed: int) -> Path:
    return Path(out) / "tasks" / pid / method / f"s{seed}.json"


def run_active_task(
    plan_file: str, pid: str, plan: str, method: dict, robot: dict, stops: int, stop_coverage: float, seed: int,
    run_seed: int, out: str, h: str, _deps=None,
) -> dict:  # fmt: skip
    """One exploration run (plan x spec seed ``seed`` x method, run with ``run_seed``); writes and returns its
    record (module docstring)."""
    from ogm_ppl.experiment.tasks import _write_json, task_env
    from ogm_ppl.exploration.active import Method, Robot, explore
    from ogm_ppl.grid import Grid

    with np.load(plan_file, allow_pickle=False) as z:
        truth, known, res = z["truth"].astype(bool), z["known"].astype(bool), float(z["resolution"])
    grid = Grid(truth.shape, resolution=res)
    kw: dict = {k: (tuple(v) if k == "patch" and v is not None else v) for k, v in method.items()}
    m = Method(**kw)
    t0 = time.perf_counter()
    with task_env():
        run = explore(
            truth, grid, m, Robot(**robot), stops=stops, seed=run_seed, stop_coverage=stop_coverage, mask=known
        )
    seconds = time.perf_counter() - t0
    rec = {
        "hash": h,
        "plan": plan,
        "plan_id": pid,
        "shape": list(truth.shape),
        "method": m.name,
        "seed": seed,
        "run_seed": run_seed,
        "seconds": seconds,
        "stopped": run.stopped,
        "stops": len(run.records),
        "path_to": {k: run.path_to(k, v) for k, v in LEVELS.items()},
        "final": {k: run.records[-1][k] for k in ("coverage", "f1", "nll_bits", "path_length", "collisions")},
        "records": run.records,
        "route": run.route.tolist(),
        "start": run.settings["start"],
    }
    _write_json(task_path(Path(out), pid, m.name, seed), rec)
    return rec


# ------------------------------------------------------------------------------------------ summary
@dataclass
class ActiveResult:
    """What :func:`run_active` did: ``runs`` (one record per task, without the per-stop records' bulk),
    ``summary`` (one row per method), executed / skipped task ids, failed id -> error, seconds, files."""

    spec: ActiveSpec
    out_dir: Path
    runs: list = field(default_factory=list)
    summary: list = field(default_factory=list)
    executed: list = field(default_factory=list)
    skipped: list = field(default_factory=list)
    failed: dict = field(default_factory=dict)
    seconds: float = 0.0
    files: list = field(default_factory=list)

    def table(self) -> str:
        return markdown(self)


def path_levels(run: dict) -> dict:
    """``{"coverage": .., "f1": .., "coverage_0.8": .., "f1_0.8": ..}``: a run's path length to the levels of
    :data:`LEVELS` (its ``path_to``) and of :data:`MORE_LEVELS` (from its per-stop ``records``; kept when the
    run already holds them as ``path_levels``)."""
    if "path_levels" in run:
        return run["path_levels"]
    from ogm_ppl.exploration.active import path_to

    out = dict(run["path_to"])
    for k, v in MORE_LEVELS:
        out[f"{k}_{v:g}"] = path_to(run["records"], k, v)
    return out


def paired_ratio(runs: list[dict], method: str, ref: str, key: str) -> tuple[float, int]:
    """The median over (plan, seed) pairs of ``method``'s path length to the level ``key`` (of
    :func:`path_levels`) over ``ref``'s, pairs where both reach it; and how many pairs there are."""
    levels = {(r["method"], r["plan_id"], r["seed"]): path_levels(r) for r in runs if r["method"] in (method, ref)}
    ratios = []
    for (m, plan, seed), lv in levels.items():
        b = levels.get((ref, plan, seed), {}).get(key, math.nan) if m == method else math.nan
        if np.isfinite(lv[key]) and np.isfinite(b) and b > 0:
            ratios.append(lv[key] / b)
    return (float(np.median(ratios)) if ratios else math.nan), len(ratios)


def summarise(runs: list[dict], methods: list[str]) -> list[dict]:
    """Per method: runs, how many reach 90 % coverage / F1 0.9 (and the levels of :data:`MORE_LEVELS`, keys
    suffixed ``_0.8``), the median path length to each over all runs (inf when fewer than half reach it), the
    median over (plan, seed) pairs of the ratio to the first method's path length (:func:`paired_ratio`),
    mean wall seconds, mean final coverage / F1 / NLL."""
    rows = []
    keys = list(LEVELS) + [f"{k}_{v:g}" for k, v in MORE_LEVELS]
    for name in methods:
        rs = [r for r in runs if r["method"] == name]
        if not rs:
            continue
        row: dict = {"method": name, "runs": len(rs), "seconds": float(np.mean([r["seconds"] for r in rs]))}
        for k in keys:
            d = np.array([path_levels(r)[k] for r in rs], dtype=float)
            row[f"reached_{k}"] = int(np.isfinite(d).sum())
            row[f"path_to_{k}"] = float(np.median(d))
            row[f"ratio_{k}"], row[f"pairs_{k}"] = paired_ratio(runs, name, methods[0], k)
        for k in ("coverage", "f1", "nll_bits", "path_length", "collisions"):
            row[f"final_{k}"] = float(np.mean([r["final"][k] for r in rs]))
        rows.append(row)
    return rows


def _f(x, nd=2) -> str:
    if x is None or (isinstance(x, float) and math.isnan(x)):
        return "–"
    return "never" if isinstance(x, float) and math.isinf(x) else f"{x:.{nd}f}"


def markdown(result: ActiveResult) -> str:
    spec = result.spec
    first = spec.methods[0]["name"]
    lines = [f"# {spec.name}", ""]
    if spec.description:
        lines += [spec.description, ""]
    nplans = len({r["plan_id"] for r in result.runs})
    lines += [
        f"{nplans} held-out {spec.corpus} plan(s) (window {spec.window} cells) x {len(spec.seeds)} seed(s); at most "
        f"{spec.stops} stops. Path length (m) to 90 % coverage of the free space and to best F1 0.9 and 0.8 of the "
        f'map: the median over runs ("never" when fewer than half reach it), how many reach it, and the median over '
        f"(plan, seed) pairs of the ratio to {first!r} (pairs where both reach it). Final values: means after the last "
        "stop.",
        "",
        "| method | path to 90 % cov. | reached | ratio | path to F1 0.9 | reached | ratio | path to F1 0.8 | reached "
        "| ratio | final cov. | final F1 | final NLL bits | path m | collisions | wall s / run |",
        "|---" * 16 + "|",
    ]
    for r in result.summary:
        lines.append(
            f"| {r['method']} | {_f(r['path_to_coverage'])} | {r['reached_coverage']}/{r['runs']} | "
            f"{_f(r['ratio_coverage'], 3)} | {_f(r['path_to_f1'])} | {r['reached_f1']}/{r['runs']} | "
            f"{_f(r['ratio_f1'], 3)} | {_f(r['path_to_f1_0.8'])} | {r['reached_f1_0.8']}/{r['runs']} | "
            f"{_f(r['ratio_f1_0.8'], 3)} | {_f(r['final_coverage'], 3)} | {_f(r['final_f1'], 3)} | "
            f"{_f(r['final_nll_bits'], 3)} | {_f(r['final_path_length'])} | {_f(r['final_collisions'], 1)} | "
            f"{_f(r['seconds'], 1)} |"
        )
    lines.append("")
    if result.failed:
        lines += ["## Failed tasks", ""] + [f"- `{k}`: {v}" for k, v in result.failed.items()] + [""]
    return "\n".join(lines)


def _curves(result: ActiveResult, path: Path) -> Path:
    from ogm_ppl.experiment.figures import _line_plot, _plt, _save_closed

    plt = _plt()
    runs = result.runs
    top = max((r["records"][-1]["path_length"] for r in runs), default=1.0) or 1.0
    x = np.linspace(0.0, top, 200)
    keys = (("coverage", "coverage of the free space"), ("f1", "best F1"), ("nll_bits", "NLL (bits / cell)"))
    fig, axes = plt.subplots(1, 3, figsize=(13, 3.8))
    for m in result.spec.methods:
        rs = [r for r in runs if r["method"] == m["name"]]
        if not rs:
            continue
        for ax, (k, _) in zip(axes, keys):
            rows = []
            for r in rs:
                d = np.array([s["path_length"] for s in r["records"]])
                v = np.array([s[k] for s in r["records"]])
                rows.append(v[np.searchsorted(d, x, side="right") - 1])  # the value after the last stop before x
            lo, med, hi = np.quantile(np.array(rows), [0.25, 0.5, 0.75], axis=0)
            (line,) = ax.plot(x, med, label=f"{m['name']} ({len(rs)} runs)")
            ax.fill_between(x, lo, hi, color=line.get_color(), alpha=0.2)
    for ax, (k, label) in zip(axes, keys):
        if k in LEVELS:
            ax.axhline(LEVELS[k], color="grey", lw=0.8, ls="--")
        _line_plot(ax, "path length (m)", label, f"{label}: median, 25-75 % band")
    return _save_closed(plt, fig, path, result.spec.dpi)


# ------------------------------------------------------------------------------------------ running
def run_active(
    spec: ActiveSpec, out_dir, *, scheduler=None, workers: int | None = None, resume: bool = True, progress: bool = True
) -> ActiveResult:
    """Run an active spec into ``out_dir`` (the scheduler options of
    :func:`~ogm_ppl.experiment.run_experiment`); raises :class:`~ogm_ppl.experiment.ExperimentError` (with
    ``.result``) when tasks failed, after writing what the finished ones allow."""
    from ogm_ppl.experiment import tasks as T
    from ogm_ppl.experiment.runner import (
        SCRATCH,
        Task,
        claim_output_folder,
        execute_tasks,
        failed_error,
        record_failures,
    )
    from ogm_ppl.experiment.tasks import _savez

    t0 = time.perf_counter()
    out = Path(out_dir)
    claim_output_folder(out, spec.name)
    if spec.source != "<dict>" and Path(spec.source).exists():
        atomic_write_text(out / "spec.toml", Path(spec.source).read_text(encoding="utf-8"))
    atomic_write_text(out / "spec.json", json.dumps(spec.to_json(), indent=1, default=str))
    maps = heldout_maps(spec.corpus, spec.count, spec.window)
    if len(maps) < spec.count:
        raise SpecError(f"{spec.source}: plans.count: only {len(maps)} held-out {spec.corpus} plans qualify")
    for m in spec.methods:  # leakage: refused before anything runs
        prior = m.get("prior")
        train = prior.partition(":")[2] or None if prior else None
        if prior is not None:
            check_heldout(spec.corpus, [t.plan for t in maps], train)
    plans = []
    for i, t in enumerate(maps):
        pid = f"p{i:02d}"
        f = _plan_path(out, pid)
        _savez(f, truth=t.truth, known=t.known, resolution=np.float64(t.resolution))
        plans.append((pid, t.name, f))
    tasks = []
    for pid, pname, f in plans:
        for s in spec.seeds:
            for m in spec.methods:
                seed = derive_seed(spec.seed, "active", pname, s)  # shared by the methods: same start and noise
                h = T.task_hash("active", pname, spec.window, m, spec.robot, spec.stops, spec.stop_coverage, seed)
                args = (str(f), pid, pname, m, spec.robot, spec.stops, spec.stop_coverage, s, seed, str(out), h)
                tasks.append(
                    Task(
                        f"active/{pid}/{m['name']}/s{s}",
                        "run",
                        run_active_task,
                        args,
                        {},
                        [],
                        task_path(out, pid, m["name"], s),
                        h,
                    )
                )
    todo, skipped, recs, results, failed = execute_tasks(
        tasks, scheduler, workers, resume, progress, scratch=out / SCRATCH
    )
    recs.update(results)
    runs = [{k: v for k, v in recs[t.id].items() if k != "hash"} for t in tasks if t.id in recs]
    result = ActiveResult(spec, out, runs=runs, executed=[t.id for t in todo if t.id in results], skipped=skipped)
    result.failed = failed
    result.summary = summarise(runs, [m["name"] for m in spec.methods])
    doc = {
        "format": "ogm_ppl.experiment.active",
        "format_version": 1,
        "provenance": provenance(),
        "experiment": spec.name,
        "seed": spec.seed,
        "plans": [{"id": pid, "plan": pname} for pid, pname, _ in plans],
        "summary": result.summary,
        "runs": [
            {**{k: v for k, v in r.items() if k not in ("records", "route")}, "path_levels": path_levels(r)}
            for r in runs
        ],
        "failed": failed,
    }
    files = [
        atomic_write_text(out / "metrics.json", json.dumps(doc, indent=1, allow_nan=True)),
        atomic_write_text(out / "metrics.md", markdown(result)),
    ]
    if spec.figures and runs:
        files.append(_curves(result, out / "figures" / "active_curves.png"))
    result.files = files
    result.seconds = time.perf_counter() - t0
    if failed:
        raise failed_error(failed, todo, result, out)
    record_failures(out, failed)
    return result
