r"""Map methods by name: one registry for every way the library makes a map.

=================  ============================================================================
``ogm``            log-odds occupancy grid mapping with any update term Delta (Section 2.4); aliases
                   ``p21`` and ``elfes`` preset the thesis's terms (Table 2.1, 2.2)
``patch_map``      the online or offline patch map (Section 3.2); alias ``patch``: offline, overlapping
``gibbs``          Gibbs sampling of the full posterior (Chapter 4): ``CellGibbs``, or ``PatchGibbs``
                   for patches of more than one cell (Algorithms 1, 2)
``metropolis``     single-cell Metropolis-Hastings (``MetropolisCell``: uniform or end-point proposals)
``vi``             variational inference with a mean-field, patch or first-hit guide
``amortised``      the amortised guide's one-pass map ``q(m_k = 1 | z)``
``guided_gibbs``   Gibbs sweeps mixed with block proposals from the amortised guide
``tempering``      parallel tempering: tempered Gibbs chains with swaps, the cold chain's marginals
=================  ============================================================================

Each has a parameter dataclass (:mod:`~ogm_ppl.methods.params`: kinds, ranges, unknown keys refused,
errors naming the key) and one entry point ``run(params, problem, ctx) -> MapResult``
(:mod:`~ogm_ppl.methods.problem`). :mod:`~ogm_ppl.methods.registry` says how to add one; a method that
runs a map kernel of its own takes :class:`SamplingParams` (the model's parameters, the run's length,
chains, checkpoints and records) and hands its kernel to :func:`run_kernel`, which runs it as the shipped
samplers run (checkpoints, resume, records, progress).

>>> from ogm_ppl.methods import get_method
>>> method = get_method("gibbs")
>>> method.parse({"sweeps": 20, "patch": [3, 3]}).patch
[3, 3]
"""

from ogm_ppl.methods._model import ModelParams
from ogm_ppl.methods._sampling import SamplingParams, run_kernel
from ogm_ppl.methods.params import (
    Block,
    Bool,
    Choice,
    DeltaName,
    Float,
    GuideFile,
    Int,
    Kind,
    Optional,
    Pair,
    ParamError,
    Patch,
    PriorName,
    Text,
    param,
    param_fields,
    parse_params,
)
from ogm_ppl.methods.problem import DEFAULT_SIGMA_CELLS, MapProblem, MapResult, RunContext
from ogm_ppl.methods.registry import (
    ENTRY_POINT_GROUP,
    ENV_VAR,
    MapMethod,
    MethodModuleError,
    get_method,
    load_extensions,
    method_names,
    methods,
    register_method,
    unregister_method,
)

__all__ = [
    "Block",
    "Bool",
    "Choice",
    "DEFAULT_SIGMA_CELLS",
    "DeltaName",
    "ENTRY_POINT_GROUP",
    "ENV_VAR",
    "Float",
    "GuideFile",
    "Int",
    "Kind",
    "MapMethod",
    "MapProblem",
    "MapResult",
    "MethodModuleError",
    "ModelParams",
    "Optional",
    "Pair",
    "ParamError",
    "Patch",
    "PriorName",
    "RunContext",
    "SamplingParams",
    "Text",
    "get_method",
    "load_extensions",
    "method_names",
    "methods",
    "param",
    "param_fields",
    "parse_params",
    "register_method",
    "run_kernel",
    "unregister_method",
]
