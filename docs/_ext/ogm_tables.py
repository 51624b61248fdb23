"""Sphinx extension: the ``ogm-table`` directive renders a table generated from a JSON snapshot.

``{ogm-table} NAME`` (MyST) or ``.. ogm-table:: NAME`` (reST) builds :func:`gen_docs_tables.table` of
``NAME`` from ``docs/results/*.json`` and writes it as a docutils table with its caption, and under it the
command, commit and machine that produced the numbers. Tables are never typed into the pages: rerun the
command, snapshot its JSON (``python tools/gen_docs_tables.py snapshot ...``) and rebuild.
"""

from __future__ import annotations

import sys
from pathlib import Path

from docutils import nodes
from docutils.parsers.rst import Directive, directives

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "tools"))

import gen_docs_tables  # noqa: E402


def _inline(text: str) -> list[nodes.Node]:
    """``text`` with its ``code`` spans as literals (the only inline markup the tables use)."""
    out: list[nodes.Node] = []
    for i, part in enumerate(text.split("`")):
        if part:
            out.append(nodes.literal(part, part) if i % 2 else nodes.Text(part))
    return out


def _row(cells: list[str]) -> nodes.row:
    row = nodes.row()
    for c in cells:
        entry = nodes.entry()
        entry += nodes.paragraph("", "", *_inline(c))
        row += entry
    return row


class OgmTable(Directive):
    required_arguments = 1
    has_content = False
    option_spec = {"name": directives.unchanged}

    def run(self) -> list[nodes.Node]:
        name = self.arguments[0]
        if name not in gen_docs_tables.TABLES:
            raise self.error(f"ogm-table: unknown table {name!r}; known: {', '.join(sorted(gen_docs_tables.TABLES))}")
        snap = gen_docs_tables.TABLES[name][0]
        env = self.state.document.settings.env
        env.note_dependency(str(gen_docs_tables.RESULTS / f"{snap}.json"))
        for tool in sorted(Path(gen_docs_tables.__file__).parent.glob("*tables*.py")):  # the builders' modules
            env.note_dependency(str(tool))
        try:
            t = gen_docs_tables.table(name)
        except FileNotFoundError:
            raise self.error(
                f"ogm-table {name}: no snapshot docs/results/{snap}.json (run the command that writes "
                "it, then python tools/gen_docs_tables.py snapshot ...)"
            ) from None
        table = nodes.table(classes=["ogm-generated"])
        table += nodes.title(t.caption, t.caption)
        group = nodes.tgroup(cols=len(t.header))
        table += group
        for _ in t.header:
            group += nodes.colspec(colwidth=1)
        head = nodes.thead()
        head += _row(t.header)
        group += head
        body = nodes.tbody()
        for r in t.rows:
            body += _row(r)
        group += body
        tail = "From " + gen_docs_tables.provenance_line(t.provenance) + (f"; {t.note}" if t.note else "") + "."
        return [table, nodes.paragraph("", "", *_inline(tail), classes=["ogm-provenance"])]


def setup(app):
    app.add_directive("ogm-table", OgmTable)
    return {"version": "1", "parallel_read_safe": True, "parallel_write_safe": True}
