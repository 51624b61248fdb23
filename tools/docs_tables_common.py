"""What the table builders of ``tools/gen_docs_tables.py`` share: the :class:`Table` they return and the
number formats of their cells."""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
RESULTS = ROOT / "docs" / "results"


@dataclass(frozen=True)
class Table:
    """One generated table: a caption, a header row, body rows (strings) and where the numbers came from."""

    caption: str
    header: list[str]
    rows: list[list[str]]
    provenance: dict
    note: str = ""


# ------------------------------------------------------------------------------------------ formatting
def _f(x, digits: int = 3) -> str:
    if x is None or (isinstance(x, float) and math.isnan(x)):
        return "–"
    return f"{x:.{digits}f}"


def _g(x, digits: int = 3) -> str:
    if x is None or (isinstance(x, float) and math.isnan(x)):
        return "–"
    return f"{x:.{digits}g}"


def _rate(x: float) -> str:
    return f"{x / 1e6:.2f} M" if x >= 1e6 else f"{x / 1e3:.0f} k"


PROVENANCE_KEYS = ("command", "commit", "machine", "date")


def load_snapshot(name: str, results: Path = RESULTS) -> dict:
    """``docs/results/NAME.json``, validated: a JSON object with a complete ``"provenance"`` block."""
    path = results / f"{name}.json"
    doc = json.loads(path.read_text())
    if not isinstance(doc, dict):
        raise ValueError(f"{path}: a snapshot is a JSON object")
    prov = doc.get("provenance")
    missing = [k for k in PROVENANCE_KEYS if not isinstance(prov, dict) or k not in prov]
    if missing:
        raise ValueError(f"{path}: provenance lacks {', '.join(missing)}")
    return doc


def join_provenance(old_p: dict, new_p: dict) -> dict:
    """The provenance of numbers from two runs: the later run's stamp, both commands (the earlier first) and
    each part's stamp under ``"parts"`` (:func:`provenance_line` prints them)."""
    prov = {k: new_p[k] for k in PROVENANCE_KEYS}
    prov["command"] = f"{old_p['command']}; then {new_p['command']}"
    prov["parts"] = [*(old_p["parts"] if "parts" in old_p else [old_p]), new_p]
    if "dropped" in old_p or "dropped" in new_p:
        prov["dropped"] = old_p.get("dropped") or new_p.get("dropped")
    return prov
