"""Experiment kinds: one table from ``[experiment] kind`` to the functions that read and run such a spec.

A kind is a :class:`ExperimentKind`: ``parse(data, source, base_dir) -> spec`` (validate the TOML table with the
toolkit of :mod:`~ogm_ppl.experiment.spec_tables`, so errors name the file, the table and the key) and
``run(spec, out_dir, *, scheduler, workers, resume, progress) -> result``. The shipped kinds:

* ``map`` (the default): datasets x map methods x chains (:mod:`~ogm_ppl.experiment.spec`,
  :func:`~ogm_ppl.experiment.runner.run_map_experiment`);
* ``active``: exploration rules on held-out plans (:mod:`~ogm_ppl.experiment.active`).

:func:`register_experiment_kind` adds a kind of one's own; :func:`parse_spec`, :func:`load_spec` and
:func:`run_experiment` (and ``ogm-ppl experiment SPEC``) dispatch on the kind and never on anything else.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ogm_ppl.experiment.active import parse_active_spec, run_active
from ogm_ppl.experiment.runner import run_map_experiment
from ogm_ppl.experiment.spec import parse_map_spec
from ogm_ppl.experiment.spec_tables import SpecError, read_spec_file

__all__ = [
    "ExperimentKind",
    "experiment_kinds",
    "load_spec",
    "parse_spec",
    "register_experiment_kind",
    "run_experiment",
]


@dataclass(frozen=True)
class ExperimentKind:
    """How a spec of one kind is read (``parse(data, source, base_dir)``) and run (``run(spec, out_dir, *,
    scheduler, workers, resume, progress)``). The spec ``parse`` returns carries its kind as ``spec.kind``
    (a spec without one is a ``map`` spec)."""

    name: str
    parse: Callable[[dict, str, Path], Any]
    run: Callable[..., Any]


_KINDS: dict[str, ExperimentKind] = {}


def register_experiment_kind(kind: ExperimentKind) -> None:
    """Add ``kind``; a name another kind took is refused (``ValueError``)."""
    if not isinstance(kind.name, str) or not kind.name.isidentifier():
        raise ValueError(f"an experiment kind is named by an identifier, got {kind.name!r}")
    old = _KINDS.get(kind.name)
    if old is not None and old != kind:
        raise ValueError(f"experiment kind {kind.name!r} is already registered")
    _KINDS[kind.name] = kind


def experiment_kinds() -> tuple[str, ...]:
    """The registered kinds' names."""
    return tuple(_KINDS)


register_experiment_kind(ExperimentKind("map", parse_map_spec, run_map_experiment))
register_experiment_kind(ExperimentKind("active", parse_active_spec, run_active))


def _kind_of(data: object, source: str) -> ExperimentKind:
    if not isinstance(data, dict):
        raise SpecError(f"{source}: a spec is a table, got {type(data).__name__}")
    exp = data.get("experiment", {})
    name = exp.get("kind", "map") if isinstance(exp, dict) else "map"  # a bad [experiment] is the kind's to name
    if name not in _KINDS:
        raise SpecError(f"{source}: experiment.kind: must be one of {', '.join(map(repr, _KINDS))}, got {name!r}")
    return _KINDS[name]


def parse_spec(data: dict, source: str = "<dict>", base_dir: str | os.PathLike = ".") -> Any:
    """Validate a spec given as a dict (the parsed TOML) with the parser of its ``[experiment] kind``
    (default ``map``); ``source`` names it in errors, ``base_dir`` anchors its relative paths."""
    return _kind_of(data, source).parse(data, source, Path(base_dir))


def load_spec(path: str | os.PathLike) -> Any:
    """Read and validate a TOML spec file (:func:`parse_spec`); raises :class:`SpecError`."""
    path = Path(path)
    return parse_spec(read_spec_file(path), str(path), path.resolve().parent)


def run_experiment(
    spec_or_path: Any,
    out_dir: str | os.PathLike,
    *,
    scheduler: Any = None,
    workers: int | None = None,
    resume: bool = True,
    progress: bool = True,
) -> Any:
    """Run a spec (a path, or what :func:`parse_spec` returned) into ``out_dir`` with the runner of its kind.

    Args:
        scheduler: ``None`` (a ``LocalCluster`` of ``workers`` processes, one thread each; default one
            per core), ``"serial"`` (no dask), ``"tcp://..."`` (a running scheduler) or a ``Client``.
        workers: LocalCluster size.
        resume: skip tasks already done with the same settings and resume stopped chains from their
            checkpoints; ``False`` recomputes everything.
        progress: progress over tasks (a bar on a terminal, plain lines to stderr otherwise).

    Returns:
        the kind's result (:class:`~ogm_ppl.experiment.runner.ExperimentResult` for ``map``); raises
        :class:`~ogm_ppl.experiment.runner.ExperimentError` (with ``.result``) if tasks failed, after writing
        what the finished tasks allow.
    """
    spec = load_spec(spec_or_path) if isinstance(spec_or_path, (str, os.PathLike)) else spec_or_path
    kind = _KINDS.get(getattr(spec, "kind", "map"))
    if kind is None:
        raise SpecError(f"{getattr(spec, 'source', spec)!r}: no experiment kind {getattr(spec, 'kind', None)!r}")
    return kind.run(spec, out_dir, scheduler=scheduler, workers=workers, resume=resume, progress=progress)
