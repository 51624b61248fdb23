r"""Run an experiment spec: independent tasks on dask.distributed (or in this process), resumable.

:func:`run_map_experiment` plans the tasks of :mod:`ogm_ppl.experiment.tasks` (a base per shared dataset
part, a dataset per expanded entry, a run per dataset x algorithm x chain, a score per dataset x
algorithm), skips those whose done-file is there with the same hash (``resume=True``; a Gibbs run that
was stopped resumes from its checkpoint), runs the others, then writes ``metrics.json``, ``metrics.md``
and the figures.

Schedulers: ``None`` starts a ``LocalCluster`` (processes, ``workers`` of them, default one per core,
one thread each), ``"serial"`` runs everything here without dask, ``"tcp://host:port"`` connects to a
running scheduler (its workers must see ``out_dir`` at the same path, e.g. a shared file system, and
should run one thread each), and a ``distributed.Client`` is used as it is. The seeds of the tasks do
not depend on the scheduler, so every scheduler gives the same numbers.
"""

from __future__ import annotations

import json
import logging
import os
import shutil
import time
import traceback
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ogm_ppl.experiment import tasks as T
from ogm_ppl.experiment.spec import ExperimentSpec
from ogm_ppl.experiment.spec_tables import derive_seed
from ogm_ppl.io import atomic_write_text
from ogm_ppl.progress import Progress

__all__ = ["ExperimentResult", "ExperimentError", "run_map_experiment", "plan_tasks"]


class ExperimentError(RuntimeError):
    """Some tasks failed; the finished ones are kept (rerun to resume). ``result`` holds what was done."""

    def __init__(self, msg, result=None):
        super().__init__(msg)
        self.result = result


@dataclass
class Task:
    id: str
    kind: str  # base | dataset | run | score
    fn: Callable[..., Any]
    args: tuple
    kwargs: dict
    deps: list
    done_file: Path
    hash: str


@dataclass
class ExperimentResult:
    """What :func:`run_map_experiment` did and measured.

    Attributes:
        scores: one record per dataset x algorithm (``mask`` and ``touched`` blocks: best F1, threshold,
            precision and recall at it, AUC, ..., and the P-R curve).
        pooled: one record per condition x algorithm: counts summed over the condition's repeats.
        runs: one record per run task (seconds, Gibbs F1-against-time trace).
        executed / skipped: task ids run now / found done; failed: task id -> error.
        provenance: what produced the outputs (:func:`ogm_ppl.provenance.provenance`: command, commit,
            machine, date), written into ``metrics.json`` and under ``metrics.md``.
    """

    spec: ExperimentSpec
    out_dir: Path
    scores: list = field(default_factory=list)
    pooled: list = field(default_factory=list)
    runs: list = field(default_factory=list)
    datasets: list = field(default_factory=list)
    executed: list = field(default_factory=list)
    skipped: list = field(default_factory=list)
    failed: dict = field(default_factory=dict)
    seconds: float = 0.0
    files: list = field(default_factory=list)
    provenance: dict = field(default_factory=dict)

    def table(self) -> str:
        """The Markdown results table (as in ``metrics.md``)."""
        from ogm_ppl.experiment.report import markdown

        return markdown(self)


# ------------------------------------------------------------------------------------------ planning
def plan_tasks(spec: ExperimentSpec, out: Path, resume: bool = True, progress: bool = False) -> list[Task]:
    """The tasks of ``spec`` in dependency order; ``progress``: a run task prints the progress of a long run
    (plain lines, labelled ``DATASET/ALGORITHM/cN``)."""
    out = Path(out)
    m, o = T.spec_entry(spec.metrics), T.spec_entry(spec.output)
    tasks: list[Task] = []
    base_h, ds_h, run_h = {}, {}, {}
    for ds in spec.datasets:
        if ds.base not in base_h:
            plan_version = [T.PLAN_BASE_VERSION] if "plan" in ds.base_params else []
            h = T.task_hash("base", ds.base_params, *plan_version, *T.base_source(ds))
            base_h[ds.base] = h
            tasks.append(
                Task(
                    f"base/{ds.base}",
                    "base",
                    T.run_base,
                    (ds, str(out), h),
                    {"max_cells": spec.max_cells},
                    [],
                    T.base_dir(out) / f"{ds.base}.json",
                    h,
                )
            )
        h = T.task_hash("dataset", ds.params, base_h[ds.base])
        ds_h[ds.name] = h
        tasks.append(
            Task(
                f"dataset/{ds.name}",
                "dataset",
                T.run_dataset,
                (ds, str(out), h),
                {},
                [f"base/{ds.base}"],
                out / "datasets" / f"{ds.name}.json",
                h,
            )
        )
    priors = {alg.name: T.algorithm_prior_digest(alg) for alg in spec.algorithms}  # a changed prior reruns its runs
    for ds in spec.datasets:
        for alg in spec.algorithms:
            hs = []
            for c in range(alg.chains):
                seed = derive_seed(spec.seed, "run", ds.name, alg.name, c)
                rec_metrics = T.records_key(spec.metrics, ds) if alg.records_metrics else None
                run_of = (ds_h[ds.name], T.spec_entry(alg), c, seed, rec_metrics, o["maps"])
                h = T.task_hash("run", *run_of, *([priors[alg.name]] if priors[alg.name] else []))
                hs.append(h)
                tid = f"run/{ds.name}/{alg.name}/c{c}"
                run_h[tid] = h
                tasks.append(
                    Task(
                        tid,
                        "run",
                        T.run_algorithm,
                        (ds, alg, c, seed, spec.metrics, spec.output, str(out), h),
                        {"resume": resume, "progress": progress},
                        [f"dataset/{ds.name}"],
                        T.run_dir(out, ds, alg, c) / "result.json",
                        h,
                    )
                )
            h = T.task_hash("score", hs, m, o["maps"])
            tasks.append(
                Task(
                    f"score/{ds.name}/{alg.name}",
                    "score",
                    T.run_score,
                    (ds, alg, spec.metrics, spec.output, str(out), h),
                    {},
                    [f"run/{ds.name}/{alg.name}/c{c}" for c in range(alg.chains)],
                    T.score_path(out, ds, alg),
                    h,
                )
            )
    return tasks


# ------------------------------------------------------------------------------------------ executing
#: the file in the output folder that holds the tracebacks of the tasks that failed in the last run
FAILURES = "failures.txt"


class TaskFailure(str):
    """A failed task's error as one line (``"ValueError: ..."``), with its Python traceback in
    :attr:`traceback` (the text :data:`FAILURES` keeps)."""

    traceback: str

    def __new__(cls, line: str, tb: str = "") -> TaskFailure:
        obj = super().__new__(cls, line)
        obj.traceback = tb
        return obj


def _failure(e: BaseException, tb) -> TaskFailure:
    return TaskFailure(f"{type(e).__name__}: {e}", "".join(traceback.format_exception(type(e), e, tb)))


#: worker log records the runner's own reports replace: a failed task (the runner keeps its traceback in
#: :data:`FAILURES`), and a heartbeat to a scheduler the interrupted driver has closed
_QUIET = ("Compute Failed", "Failed to communicate with scheduler during heartbeat")


def _quiet_task_failures(record: logging.LogRecord) -> bool:
    """A filter for dask workers' log: drop the records of :data:`_QUIET`."""
    return not str(record.msg).startswith(_QUIET)


def _worker_setup() -> None:
    """Run in each worker process of the runner's own ``LocalCluster``: keep "Compute Failed" reports out of
    the log (:func:`_quiet_task_failures`), and ignore Ctrl-C, which a terminal sends to every process of the
    run: the driver stops the run and closes the cluster, instead of each worker dying with a traceback."""
    import signal
    import threading

    logger = logging.getLogger("distributed.worker")
    if _quiet_task_failures not in logger.filters:
        logger.addFilter(_quiet_task_failures)
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGINT, signal.SIG_IGN)


def _execute_serial(todo: list[Task], progress: bool):
    results, failed = {}, {}
    with Progress(len(todo), "tasks", enabled=progress) as bar:
        for t in todo:
            bad = [d for d in t.deps if d in failed]
            if bad:
                failed[t.id] = f"dependency {bad[0]} failed"
            else:
                try:
                    results[t.id] = t.fn(*t.args, **t.kwargs)
                except Exception as e:  # keep going: independent tasks still finish, and a rerun resumes
                    failed[t.id] = _failure(e, e.__traceback__)
            bar.update(note=t.id)
    return results, failed


#: seconds to wait for a ``--scheduler`` address to answer before giving up
SCHEDULER_TIMEOUT_S = 5.0


def _client(scheduler, workers, scratch: Path | None = None):
    """``(client, owned)``: a Client for ``scheduler`` and whether we must close it (and its cluster). A
    ``LocalCluster``'s workers keep their scratch files in ``scratch`` (inside the output folder), not in the
    system's temporary folder."""
    from distributed import Client, LocalCluster

    if isinstance(scheduler, Client):
        return scheduler, False
    if scheduler is None:
        import dask

        n = int(workers) if workers else (os.cpu_count() or 1)
        where = {} if scratch is None else {"temporary-directory": str(scratch)}  # lock files too
        with dask.config.set(where):
            cluster = LocalCluster(
                n_workers=n,
                threads_per_worker=1,
                processes=True,
                dashboard_address=None,
                silence_logs=logging.ERROR,
                local_directory=None if scratch is None else str(scratch),
            )
        client = Client(cluster)
        client.run(_worker_setup)  # failed tasks go to failures.txt; Ctrl-C is the driver's
        return client, True
    if isinstance(scheduler, str):
        try:
            return Client(scheduler, timeout=SCHEDULER_TIMEOUT_S), True
        except (OSError, TimeoutError) as e:
            raise ConnectionError(
                f"cannot reach the dask scheduler at {scheduler!r} within {SCHEDULER_TIMEOUT_S:g} s "
                f"({type(e).__name__}: {e}); is it running, and is the address host:port?"
            ) from None
    raise TypeError(f"scheduler must be None, 'serial', an address or a distributed.Client, got {scheduler!r}")


def _execute_dask(todo: list[Task], client, progress: bool):
    from distributed import as_completed

    futures: dict[str, object] = {}  # task id -> dask Future
    by_future: dict[str, str] = {}  # Future key -> task id
    token = f"{time.time_ns():x}"
    for t in todo:
        deps = [futures[d] for d in t.deps if d in futures]
        kw = dict(t.kwargs)
        if deps:
            kw["_deps" if t.kind != "dataset" else "_base"] = deps
        f = client.submit(t.fn, *t.args, key=f"{t.id}-{token}", pure=False, **kw)
        futures[t.id] = f
        by_future[f.key] = t.id
    results, failed = {}, {}
    with Progress(len(todo), "tasks", enabled=progress) as bar:
        for f in as_completed(list(futures.values())):
            tid = by_future[f.key]
            if f.status == "finished":
                results[tid] = f.result()
            else:
                failed[tid] = _failure(f.exception(), f.traceback())
            bar.update(note=tid)
    return results, failed


def execute_tasks(
    tasks: list[Task], scheduler, workers: int | None, resume: bool, progress: bool, scratch: Path | None = None
):
    """Run the tasks not already done: ``(todo, skipped, done_records, results, failed)``.

    A task is done when its done-file holds its settings' hash (``resume``) and every task it depends on is
    done; the others run serially (``scheduler == "serial"``) or on dask (see :func:`run_map_experiment`; a local
    cluster's scratch folder is ``scratch``, removed afterwards)."""
    todo, skipped, done_recs = [], [], {}
    for t in tasks:
        rec = T.read_done(t.done_file, t.hash) if resume else None
        if rec is not None and all(d in done_recs for d in t.deps):
            done_recs[t.id] = rec
            skipped.append(t.id)
        else:
            todo.append(t)
    if scheduler == "serial" or not todo:
        results, failed = _execute_serial(todo, progress)
    else:
        client, owned = _client(scheduler, workers, scratch)
        try:
            results, failed = _execute_dask(todo, client, progress)
        finally:
            if owned:
                cluster = client.cluster
                client.close()
                if cluster is not None:
                    cluster.close()
            if scratch is not None:
                shutil.rmtree(scratch, ignore_errors=True)
    return todo, skipped, done_recs, results, failed


def record_failures(out: Path, failed: dict) -> Path | None:
    """Write each failed task's id, error and traceback to ``out/failures.txt`` (atomically), or remove the
    file a previous run left when none failed; returns the file, if written."""
    path = Path(out) / FAILURES
    if not failed:
        path.unlink(missing_ok=True)
        return None
    parts = []
    for tid, err in failed.items():
        tb = getattr(err, "traceback", "") or "(no traceback: it did not run)\n"
        parts.append(f"== {tid}: {err}\n{tb}")
    return atomic_write_text(path, "\n".join(parts))


def failed_error(failed: dict, todo: list, result, out: Path | None = None) -> ExperimentError:
    """The :class:`ExperimentError` of a run in which ``failed`` (task id -> error) of the ``todo`` tasks failed;
    with ``out``, the tracebacks are written to ``out/failures.txt`` (:func:`record_failures`), which it names."""
    deps = {t.id: t.deps for t in todo}
    own = [tid for tid in failed if not any(d in failed for d in deps.get(tid, ()))]  # not for a failed input
    first = (own or list(failed))[0]
    where = record_failures(out, failed) if out is not None else None
    tracebacks = f"; tracebacks in {where}" if where is not None else ""
    after = len(failed) - len(own)
    also = f", and {after} that depend on them" if own and after else ""
    return ExperimentError(
        f"{len(own) or len(failed)} of {len(todo)} tasks failed{also} (first: {first}: {failed[first]}{tracebacks}); "
        "finished tasks are kept: rerun to resume once the cause is mended",
        result,
    )


# ------------------------------------------------------------------------------------------ the API
#: the local dask cluster's scratch folder, inside the output folder while the tasks run
SCRATCH = ".dask-scratch"


def claim_output_folder(out: Path, name: str) -> None:
    """Create the output folder ``out`` for experiment ``name``; refuse (``ValueError``) a path that is a file,
    or a folder that holds another experiment's results (its ``spec.json`` names another experiment), rather
    than mixing two experiments' files."""
    if out.exists() and not out.is_dir():
        raise ValueError(f"output folder {out}: exists and is not a folder")
    prev = out / "spec.json"
    if prev.is_file():
        try:
            old = json.loads(prev.read_text(encoding="utf-8")).get("name")
        except (OSError, ValueError, AttributeError):
            old = None
        if isinstance(old, str) and old != name:
            raise ValueError(
                f"output folder {out}: holds the results of experiment {old!r} (its spec.json), not {name!r}; "
                "name another output folder, or delete this one"
            )
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise ValueError(f"output folder {out}: cannot be created ({e.strerror or e})") from None


def run_map_experiment(
    spec: ExperimentSpec,
    out_dir,
    *,
    scheduler=None,
    workers: int | None = None,
    resume: bool = True,
    progress: bool = True,
) -> ExperimentResult:
    """Run a spec of the kind ``map`` into ``out_dir`` (:func:`ogm_ppl.experiment.run_experiment` runs any kind).

    Args:
        scheduler: ``None`` (a ``LocalCluster`` of ``workers`` processes, one thread each; default one
            per core), ``"serial"`` (no dask), ``"tcp://..."`` (a running scheduler) or a ``Client``.
        workers: LocalCluster size.
        resume: skip tasks already done with the same settings and resume stopped Gibbs runs from their
            checkpoints; ``False`` recomputes everything.
        progress: progress over tasks (:class:`~ogm_ppl.progress.Progress`: a bar on a terminal, plain
            lines to stderr otherwise).

    Returns:
        an :class:`ExperimentResult`; raises :class:`ExperimentError` (with ``.result``) if tasks failed,
        after writing what the finished tasks allow, and ``ValueError`` before any task when ``out_dir``
        cannot be the output folder (:func:`claim_output_folder`).
    """
    t0 = time.perf_counter()
    out = Path(out_dir)
    claim_output_folder(out, spec.name)
    if spec.source != "<dict>" and Path(spec.source).exists():
        shutil.copyfile(spec.source, out / "spec.toml")
    atomic_write_text(out / "spec.json", json.dumps(spec.to_json(), indent=1, default=str))
    tasks = plan_tasks(spec, out, resume, progress)
    todo, skipped, done_recs, results, failed = execute_tasks(
        tasks, scheduler, workers, resume, progress, scratch=out / SCRATCH
    )
    recs = {**done_recs, **{k: v for k, v in results.items() if v is not None}}
    result = ExperimentResult(
        spec, out, executed=[t.id for t in todo if t.id in results], skipped=skipped, failed=failed
    )
    from ogm_ppl.experiment.report import write_outputs

    write_outputs(result, tasks, recs)
    result.seconds = time.perf_counter() - t0
    if failed:
        raise failed_error(failed, todo, result, out)
    record_failures(out, failed)
    return result


def _jsonable(x):
    if isinstance(x, (np.floating, np.integer)):
        return x.item()
    if isinstance(x, Path):
        return str(x)
    raise TypeError(type(x).__name__)
