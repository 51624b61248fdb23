"""The longest signatures of the numba-compiled functions (``@nb.njit``), to keep compiled call sites small.

    python tools/compiled_signatures.py [ROOT] [--top N]

Prints ``parameters  module:function`` for the N (default 5) njit functions with the most parameters under
``ogm_ppl/`` of ROOT (default: this checkout).
"""

from __future__ import annotations

import argparse
import ast
from pathlib import Path


def compiled_signatures(root: Path) -> list[tuple[int, str]]:
    """``(number of parameters, "path:function")`` of every njit-decorated function under ``root/ogm_ppl``."""
    out = []
    for path in sorted((root / "ogm_ppl").rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.FunctionDef) and any("njit" in ast.unparse(d) for d in node.decorator_list):
                out.append((len(node.args.args), f"{path.relative_to(root)}:{node.name}"))
    return sorted(out, key=lambda x: (-x[0], x[1]))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("root", nargs="?", type=Path, default=Path(__file__).resolve().parents[1])
    ap.add_argument("--top", type=int, default=5)
    args = ap.parse_args()
    for n, name in compiled_signatures(args.root)[: args.top]:
        print(f"{n:3d}  {name}")


if __name__ == "__main__":
    main()
