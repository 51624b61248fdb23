"""Experiments from a spec (Chapter 6): datasets x algorithms x chains as dask tasks, resumable,
scored against the truth (simulated) or the thesis's benchmark map (logs), with tables and figures. An
algorithm is any registered map method (:mod:`ogm_ppl.methods`) with its parameters; the headline run
(:mod:`~ogm_ppl.experiment.headline`) and the simulated examples (:mod:`~ogm_ppl.experiment.simple2d`)
are drivers built on them.

>>> from ogm_ppl.experiment import load_spec, run_experiment      # doctest: +SKIP
>>> result = run_experiment("my_spec.toml", "out/smoke", scheduler="serial")  # doctest: +SKIP
>>> print(result.table())                                         # doctest: +SKIP
"""

from ogm_ppl.experiment.kinds import (
    ExperimentKind,
    experiment_kinds,
    load_spec,
    parse_spec,
    register_experiment_kind,
    run_experiment,
)
from ogm_ppl.experiment.runner import ExperimentError, ExperimentResult, plan_tasks
from ogm_ppl.experiment.spec import AlgorithmSpec, DatasetSpec, ExperimentSpec, MetricsSpec, OutputSpec
from ogm_ppl.experiment.spec_tables import SpecError, derive_seed

__all__ = [
    "AlgorithmSpec",
    "DatasetSpec",
    "ExperimentError",
    "ExperimentKind",
    "ExperimentResult",
    "ExperimentSpec",
    "MetricsSpec",
    "OutputSpec",
    "SpecError",
    "derive_seed",
    "experiment_kinds",
    "load_spec",
    "parse_spec",
    "plan_tasks",
    "register_experiment_kind",
    "run_experiment",
]
