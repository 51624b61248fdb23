"""Every numba-compiled function of the library takes at most ten parameters: arguments that travel together
go into one ``typing.NamedTuple`` bundle (a state, a scratch, a rule), so compiled call sites stay short."""

from __future__ import annotations

import ast
from pathlib import Path

import ogm_ppl

MAX_PARAMETERS = 10


def _njit_signatures() -> list[tuple[int, str]]:
    """``(parameters, "path:function")`` of every function under ``ogm_ppl`` with an ``njit`` decorator."""
    root = Path(ogm_ppl.__file__).resolve().parent
    out = []
    for path in sorted(root.rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.FunctionDef) and any("njit" in ast.unparse(d) for d in node.decorator_list):
                a = node.args
                n = len(a.posonlyargs) + len(a.args) + len(a.kwonlyargs) + (a.vararg is not None)
                out.append((n, f"{path.relative_to(root.parent)}:{node.name}"))
    return out


def test_scan_finds_the_kernels() -> None:
    names = {name for _, name in _njit_signatures()}
    assert "ogm_ppl/_raycast_kernels.py:trace_ray" in names
    assert len(names) > 100


def test_no_compiled_function_takes_more_than_ten_parameters() -> None:
    long = sorted((n, name) for n, name in _njit_signatures() if n > MAX_PARAMETERS)
    assert not long, f"njit functions with more than {MAX_PARAMETERS} parameters (bundle them): {long}"
