r"""The registry of map methods: every way the library makes a map, by name.

A method is a function ``run(params, problem, ctx) -> MapResult`` (:mod:`~ogm_ppl.methods.problem`) and a
frozen parameter dataclass (:mod:`~ogm_ppl.methods.params`), registered under a name with
:func:`register_method`. The command line (``ogm-ppl map --method NAME --param key=value``,
``ogm-ppl methods``), experiment specs (``[[algorithms]] kind = "NAME"``) and the experiment's tasks all
find methods here, and nothing else branches on method names.

**Adding a method is one file.** Put a module in ``ogm_ppl/methods/`` (it is imported when the registry
is first used; modules whose names start with ``_`` are not), or anywhere else and name it in the
environment variable ``OGM_PPL_METHODS`` (comma-separated modules), or as an entry point of the group
``ogm_ppl.methods`` in a package's metadata, or simply import it before use::

    from dataclasses import dataclass
    from ogm_ppl.methods import Float, MapResult, param, register_method

    @dataclass(frozen=True)
    class ThresholdParams:
        level: float = param(0.5, Float(0, 1), "occupancy given to cells a beam ended in")

    @register_method("endpoints", ThresholdParams)
    def endpoints(params, problem, ctx):
        '''Cells holding a beam's end point get ``level``, the rest 0 (a toy).'''
        p = np.zeros(problem.grid.num_cells)
        p[problem.rays.endpoint_cells()] = params.level
        return MapResult(p, problem.rays.reached())

The first docstring line is the method's one-line description (``ogm-ppl methods``). An experiment run
on dask workers (other processes) finds a method outside this package only through ``OGM_PPL_METHODS``
or an entry point, which every process reads; a module imported by hand registers in its own process.
"""

from __future__ import annotations

import dataclasses
import importlib
import os
import pkgutil
import time
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass, field
from typing import Any

from ogm_ppl.extensions import ENTRY_POINT_GROUP, ENV_VAR, MethodModuleError
from ogm_ppl.extensions import load_extensions as _load_extension_modules
from ogm_ppl.methods.params import ParamError, param_fields, parse_params
from ogm_ppl.methods.problem import MapProblem, MapResult, RunContext

__all__ = [
    "ENTRY_POINT_GROUP",
    "ENV_VAR",
    "MapMethod",
    "MethodModuleError",
    "get_method",
    "load_extensions",
    "method_names",
    "methods",
    "register_method",
    "unregister_method",
]

_INFRASTRUCTURE = {"params", "problem", "registry"}
_FIRST = ("log_odds", "patch_map", "gibbs")  # listed first: the thesis's order

RunFunction = Callable[[Any, MapProblem, RunContext], MapResult]


@dataclass(frozen=True)
class MapMethod:
    """A registered method.

    Attributes:
        name: its name in specs and on the command line.
        params: its parameter dataclass.
        function: ``run(params, problem, ctx) -> MapResult``.
        doc: one line.
        defaults: parameter values replacing the dataclass's defaults (an alias such as ``p21``, which is
            ``ogm`` with ``delta = "p21"``).
        alias_of: the method an alias presets, else ``None``.
        stochastic: it draws from torch's global generator (one such run at a time per process).
        sampler: its result records scores of running marginals (``ctx.score``), so they depend on the
            experiment's metrics; it has a ``chains`` parameter.
    """

    name: str
    params: type
    function: RunFunction
    doc: str
    defaults: Mapping[str, Any] = field(default_factory=dict)
    alias_of: str | None = None
    stochastic: bool = False
    sampler: bool = False

    def parse(self, values: Mapping[str, Any], *, text: bool = False):
        """The parameters from ``values`` over this method's defaults (:func:`~.params.parse_params`)."""
        return parse_params(self.params, values, text=text, defaults=self.defaults)

    def default_params(self):
        """The parameters with every default."""
        return self.parse({})

    def param_names(self) -> list[str]:
        return [name for name, *_ in param_fields(self.params)]

    def run(self, params, problem: MapProblem, ctx: RunContext | None = None) -> MapResult:
        """Run the method; fills ``result.seconds`` (ray casting done in this call, and the rest)."""
        if not isinstance(params, self.params):
            raise TypeError(f"method {self.name!r} takes {self.params.__name__}, not {type(params).__name__}")
        ctx = RunContext() if ctx is None else ctx
        check_size = getattr(params, "check_size", None)
        if check_size is not None:  # work that would not fit (memory, time) refused before any of it is done
            check_size(problem)
        before = problem.ray_cast_seconds
        t0 = time.perf_counter()
        result = self.function(params, problem, ctx)
        total = time.perf_counter() - t0
        ray = problem.ray_cast_seconds if problem.ray_cast_seconds is not before else None
        result.seconds = {"ray_cast": ray, "map": total - (ray or 0.0), **result.seconds}
        if result.probabilities is not None:
            import numpy as np

            p = np.asarray(result.probabilities, dtype=np.float64)
            if p.ndim > 1 and p.shape != problem.grid.shape:  # a transposed map would ravel into wrong cells
                raise ValueError(
                    f"method {self.name!r} returned probabilities of shape {p.shape}: give the grid's "
                    f"{problem.grid.shape} (rows, cols) or its {problem.grid.num_cells} cells in row-major order"
                )
            result.probabilities = p.ravel()
            if result.probabilities.shape != (problem.grid.num_cells,):
                raise ValueError(
                    f"method {self.name!r} returned {result.probabilities.shape} probabilities "
                    f"for {problem.grid.num_cells} cells"
                )
        return result

    def describe(self) -> list[str]:
        """Lines for ``ogm-ppl methods``: the name, the doc, and each parameter with kind, default, doc."""
        lines = [f"{self.name}: {self.doc}"]
        defaults = dataclasses.asdict(self.default_params())
        for name, kind, _, doc in param_fields(self.params):
            lines.append(f"    {name} = {defaults[name]!r}  ({kind.describe()}) {doc}")
        return lines


_METHODS: dict[str, MapMethod] = {}
_discovered = False


def _first_line(fn) -> str:
    doc = (fn.__doc__ or "").strip()
    return doc.splitlines()[0].strip() if doc else fn.__name__


def register_method(
    name: str,
    params: type,
    *,
    aliases: Mapping[str, Mapping[str, Any]] | None = None,
    stochastic: bool = False,
    sampler: bool = False,
    doc: str | None = None,
):
    """Decorator: register ``run(params, problem, ctx) -> MapResult`` as the method ``name`` with the
    parameter dataclass ``params`` (fields made with :func:`~.params.param`).

    ``aliases``: more names, each presetting some parameters (``{"p21": {"delta": "p21"}}``).
    ``stochastic``, ``sampler``: see :class:`MapMethod`. ``doc``: the one-line description (default: the
    first line of the function's docstring). Registering a taken name is an error.

    The dataclass may define ``check()`` (rules between its fields, run when it is parsed) and
    ``check_size(problem)``: run by :meth:`MapMethod.run` before the method, it refuses work that would not fit
    (the free memory, hours of time) with a :class:`~.params.ParamError` naming the parameter, the estimate and
    its limit.
    """
    if not dataclasses.is_dataclass(params):
        raise TypeError(f"params of method {name!r} must be a dataclass, got {params!r}")
    param_fields(params)  # every field made with param()

    def deco(fn: RunFunction) -> RunFunction:
        load_extensions()  # the library's own methods first, whoever registers
        line = doc or _first_line(fn)
        new = [MapMethod(name, params, fn, line, stochastic=stochastic, sampler=sampler)]
        for alias, preset in (aliases or {}).items():
            checked = parse_params(params, preset)
            values = {k: getattr(checked, k) for k in preset}
            text = ", ".join(f"{k} = {v!r}" for k, v in values.items())
            new.append(MapMethod(alias, params, fn, f"{name} with {text}", values, name, stochastic, sampler))
        for m in new:
            old = _METHODS.get(m.name)
            if old is not None and (old.function.__module__, old.function.__qualname__) != (
                fn.__module__,
                fn.__qualname__,
            ):
                raise ValueError(
                    f"a map method named {m.name!r} is already registered "
                    f"({old.function.__module__}.{old.function.__qualname__})"
                )
        for m in new:
            _METHODS[m.name] = m
        return fn

    return deco


def unregister_method(name: str) -> None:
    """Remove ``name`` and its aliases (tests)."""
    for key in [k for k, m in _METHODS.items() if k == name or m.alias_of == name]:
        del _METHODS[key]


def load_extensions() -> None:
    """Import the modules of this package, then the extension modules (:func:`ogm_ppl.extensions.load_extensions`:
    ``$OGM_PPL_METHODS`` and the entry points of the group ``ogm_ppl.methods``), once per process and again after
    a failed import. Every lookup of a method calls it. :class:`~ogm_ppl.extensions.MethodModuleError` names a
    module that cannot be imported."""
    global _discovered
    if _discovered:
        return
    _discovered = True  # before the imports: their register_method calls come back here
    here = os.path.dirname(__file__)  # the package's own modules, found on disk (importing the package would circle)
    names = [i.name for i in pkgutil.iter_modules([here])]
    names = sorted(n for n in names if not n.startswith("_") and n not in _INFRASTRUCTURE)
    for name in sorted(names, key=lambda n: (_FIRST.index(n) if n in _FIRST else len(_FIRST), n)):
        importlib.import_module(f"{__package__}.{name}")
    try:
        _load_extension_modules()
    except MethodModuleError:
        _discovered = False  # no half-filled registry: the next call tries again and says why again
        raise


def method_names() -> list[str]:
    """Every registered name (aliases included), in registration order."""
    load_extensions()
    return list(_METHODS)


def methods() -> Iterator[MapMethod]:
    """Every registered method (aliases included)."""
    load_extensions()
    return iter(list(_METHODS.values()))


def get_method(name: str) -> MapMethod:
    """The method ``name``; :class:`~.params.ParamError` (key ``"method"``) naming the known ones if none."""
    load_extensions()
    try:
        return _METHODS[name]
    except (KeyError, TypeError):
        raise ParamError(
            "method",
            f"unknown method {name!r}; choose from {', '.join(_METHODS)} (a method registered in a module of your "
            f"own: import it first, or name the module in ${ENV_VAR} for the command line and dask workers)",
        ) from None
