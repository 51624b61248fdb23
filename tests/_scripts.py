"""Load a script of ``experiments/`` as a module, for the tests of that script (the scripts whose tests still
load them; the others run in a fresh interpreter: :mod:`tests._experiments`)."""

import importlib.util
import sys
from pathlib import Path
from types import ModuleType

from tests._plan_folder import write_plan_folder  # the tests that still import it from here

EXPERIMENTS = Path(__file__).resolve().parents[1] / "experiments"


def load_experiment(name: str, file: str) -> ModuleType:
    """``experiments/<file>`` imported under the module name ``name`` (registered in ``sys.modules``, where
    dataclasses look their module up; pop it when done)."""
    spec = importlib.util.spec_from_file_location(name, EXPERIMENTS / file)
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    sys.modules[name] = mod
    spec.loader.exec_module(mod)
    return mod


__all__ = ["load_experiment", "write_plan_folder"]
