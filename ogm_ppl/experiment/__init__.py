"""Experiments from a spec (Chapter 6): datasets x algorithms x chains as dask tasks, resumable,
scored against the truth (simulated) or the thesis's benchmark map (logs), with tables and figures. An
algorithm is any registered map method (:mod:`ogm_ppl.methods`) with its parameters; the headline run
(:mod:`~ogm_ppl.experiment.headline`) and the simulated examples (:mod:`~ogm_ppl.experiment.simple2d`)
are drivers built on them.

>>> from ogm_ppl.experiment import load_spec, run_experiment      # doctest: +SKIP
>>> result = run_experiment("experiments/specs/smoke.toml", "out/smoke", scheduler="serial")  # doctest: +SKIP
>>> print(result.table())                                         # doctest: +SKIP
"""

from ogm_ppl.experiment.runner import ExperimentError, ExperimentResult, plan_tasks, run_experiment
from ogm_ppl.experiment.spec import (
    AlgorithmSpec,
    DatasetSpec,
    ExperimentSpec,
    MetricsSpec,
    OutputSpec,
    SpecError,
    derive_seed,
    load_spec,
    parse_spec,
)

__all__ = [
    "AlgorithmSpec",
    "DatasetSpec",
    "ExperimentError",
    "ExperimentResult",
    "ExperimentSpec",
    "MetricsSpec",
    "OutputSpec",
    "SpecError",
    "derive_seed",
    "load_spec",
    "parse_spec",
    "plan_tasks",
    "run_experiment",
]
