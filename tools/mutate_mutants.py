"""Which mutants ``tools/mutate.py`` runs: cosmic-ray's mutants of a module, the seeded sample of sites,
the mutated source and its diff."""

from __future__ import annotations

import ast
import dataclasses
import difflib
import random


@dataclasses.dataclass
class Mutant:
    module: str
    operator: str
    occurrence: int
    line: int
    site: tuple[int, int, int, int]

    @property
    def key(self) -> str:
        return f"{self.module}:{self.operator}:{self.occurrence}"


def _operators():
    import cosmic_ray.plugins

    for name in sorted(cosmic_ray.plugins.operator_names()):
        cls = cosmic_ray.plugins.get_operator(name)
        if not cls.arguments():  # the variable replacer/inserter need arguments: not used
            yield name, cls()


def enumerate_mutants(name: str, source: str) -> list[Mutant]:
    """Every cosmic-ray mutant of one module (as ``cosmic-ray init`` finds them)."""
    from cosmic_ray.ast import ast_nodes, get_ast

    lines = source.splitlines()
    nodes = list(ast_nodes(get_ast(source)))
    out = []
    for op_name, op in _operators():
        positions = [(s, e) for node in nodes for s, e in op.mutation_positions(node)]
        for occ, (start, end) in enumerate(positions):
            text = lines[start[0] - 1]
            if "pragma: no mutate" in text:
                continue
            if text.lstrip().startswith(("@nb.", "@numba.", "@njit", "@jit")):
                # numba's decorator: without it the kernel runs as Python (same numbers, only slower);
                # cache=False or a changed inline option compile the same code
                continue
            out.append(Mutant(name, op_name, occ, start[0], (*start, *end)))
    return out


def sample(mutants: list[Mutant], per_module: int | None, seed: int, name: str) -> list[Mutant]:
    """``per_module`` random sites, one random operator variant at each (all mutants when ``None``)."""
    if per_module is None:
        return list(mutants)
    rng = random.Random(f"{seed}:{name}")
    by_site: dict[tuple, list[Mutant]] = {}
    for m in mutants:
        by_site.setdefault(m.site, []).append(m)
    sites = sorted(by_site)
    rng.shuffle(sites)
    chosen = [rng.choice(by_site[s]) for s in sites[:per_module]]
    return sorted(chosen, key=lambda m: (m.line, m.operator, m.occurrence))


def annotation_spans(source: str) -> list[tuple[tuple[int, int], tuple[int, int]]]:
    """``(start, end)`` positions of the type annotations of a module that has ``from __future__ import
    annotations`` (there they are strings, never evaluated: a mutant inside one is equivalent)."""
    if "from __future__ import annotations" not in source:
        return []
    spans = []
    for n in ast.walk(ast.parse(source)):
        anns = []
        if isinstance(n, ast.arg) and n.annotation is not None:
            anns.append(n.annotation)
        elif isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef)) and n.returns is not None:
            anns.append(n.returns)
        elif isinstance(n, ast.AnnAssign):
            anns.append(n.annotation)
        spans += [((a.lineno, a.col_offset), (a.end_lineno or a.lineno, a.end_col_offset or 0)) for a in anns]
    return spans


def compiles(source: str | None, path: str) -> bool:
    try:
        compile(source or "", path, "exec")
    except SyntaxError:
        return False
    return True


def mutate_source(source: str, m: Mutant) -> str | None:
    import cosmic_ray.plugins
    from cosmic_ray.mutating import mutate_code

    return mutate_code(source, cosmic_ray.plugins.get_operator(m.operator)(), m.occurrence)


def changed_lines(original: str, mutated: str) -> tuple[str, str]:
    a, b = original.splitlines(), mutated.splitlines()
    old, new = [], []
    for tag, i1, i2, j1, j2 in difflib.SequenceMatcher(a=a, b=b, autojunk=False).get_opcodes():
        if tag != "equal":
            old += [s.strip() for s in a[i1:i2]]
            new += [s.strip() for s in b[j1:j2]]
    return " / ".join(old), " / ".join(new)


def unified_diff(original: str, mutated: str, path: str) -> str:
    return "".join(
        difflib.unified_diff(original.splitlines(True), mutated.splitlines(True), f"a/{path}", f"b/{path}", n=3)
    )
