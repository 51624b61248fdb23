"""The records the repository ships (``ogm_ppl/fitted/*.json``, ``docs/results/*.json``) name files relative to
where their command ran: no machine's folder (``/home/...``, ``/tmp/...``, a checkout's absolute path) in any key
or string value."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
RECORDS = sorted((ROOT / "ogm_ppl" / "fitted").glob("*.json")) + sorted((ROOT / "docs" / "results").glob("*.json"))
# an absolute POSIX path of two parts or more, at the start of a string or after a space or '='
ABSOLUTE = re.compile(r"(?:^|[\s=])(/[\w.+-]+(?:/[\w.+-]+)+)")


def _strings(x):
    if isinstance(x, dict):
        for k, v in x.items():
            yield str(k)
            yield from _strings(v)
    elif isinstance(x, list):
        for v in x:
            yield from _strings(v)
    elif isinstance(x, str):
        yield x


def test_the_records_exist():
    assert len(RECORDS) > 50


@pytest.mark.parametrize("path", RECORDS, ids=lambda p: f"{p.parent.name}/{p.name}")
def test_a_record_names_no_machine_folder(path):
    found = sorted({m for s in _strings(json.loads(path.read_text())) for m in ABSOLUTE.findall(s)})
    assert not found, f"{path.relative_to(ROOT)} names absolute paths: {found[:5]}"
