"""The package's import graph, every import counted (module level and inside functions): no circles.

A circle is a strongly connected component of more than one module in the graph whose edges are the
``ogm_ppl.*`` imports of each module (``from ogm_ppl.x import y`` points at ``ogm_ppl.x.y`` when that is a
module, else at ``ogm_ppl.x``). Two circles are known and listed in :data:`KNOWN`; the test fails on any other,
and on a known one that is gone (so the list only shrinks).
"""

import ast
from pathlib import Path

PKG = Path(__file__).resolve().parents[1] / "ogm_ppl"

#: circles still to be taken apart: the compiled tiles bundle and its kernels, and the experiment kinds
KNOWN = {
    frozenset({"ogm_ppl.priors.compiled.bundles", "ogm_ppl.priors.compiled.tiles"}),
    frozenset({"ogm_ppl.experiment.active", "ogm_ppl.experiment.runner", "ogm_ppl.experiment.spec"}),
}


def _modules() -> dict[str, Path]:
    out = {}
    for p in PKG.rglob("*.py"):
        parts = p.relative_to(PKG.parent).with_suffix("").parts
        out[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = p
    return out


def import_graph() -> dict[str, set[str]]:
    """Module -> the library modules it imports (anywhere in the file)."""
    mods = _modules()

    def resolve(name: str) -> str | None:
        while name and name not in mods:
            name = name.rpartition(".")[0]
        return name or None

    edges: dict[str, set[str]] = {m: set() for m in mods}
    for m, p in mods.items():
        pkg = m if p.stem == "__init__" else m.rpartition(".")[0]
        for node in ast.walk(ast.parse(p.read_text(), filename=str(p))):
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = pkg.split(".")[: len(pkg.split(".")) - (node.level - 1)] if node.level else []
                mod = ".".join(base + ([node.module] if node.module else [])) if node.level else node.module or ""
                targets = [f"{mod}.{a.name}" if f"{mod}.{a.name}" in mods else mod for a in node.names]
            else:
                continue
            for t in targets:
                r = resolve(t) if t.startswith("ogm_ppl") else None
                if r is not None and r != m:
                    edges[m].add(r)
    return edges


def circles(edges: dict[str, set[str]]) -> list[frozenset[str]]:
    """Strongly connected components of more than one module (Tarjan's algorithm, iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    out: list[frozenset[str]] = []
    for root in edges:
        if root in index:
            continue
        work = [(root, iter(sorted(edges[root])))]
        index[root] = low[root] = len(index)
        stack.append(root)
        on.add(root)
        while work:
            v, it = work[-1]
            w = next(it, None)
            if w is not None:
                if w not in index:
                    index[w] = low[w] = len(index)
                    stack.append(w)
                    on.add(w)
                    work.append((w, iter(sorted(edges[w]))))
                elif w in on:
                    low[v] = min(low[v], index[w])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[v])
            if low[v] == index[v]:
                comp = set()
                while True:
                    w = stack.pop()
                    on.discard(w)
                    comp.add(w)
                    if w == v:
                        break
                if len(comp) > 1:
                    out.append(frozenset(comp))
    return out


def test_the_circle_finder_finds_a_circle_and_a_clean_graph():
    assert circles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [frozenset("abc")]
    assert circles({"a": {"b"}, "b": {"c"}, "c": set()}) == []


def test_the_package_has_no_import_circle_but_the_known_ones():
    found = set(circles(import_graph()))
    new = [sorted(c) for c in found - KNOWN]
    assert not new, f"import circles: {new}"
    gone = [sorted(c) for c in KNOWN - found]
    assert not gone, f"these circles are gone: take them off KNOWN: {gone}"
