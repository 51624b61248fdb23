"""What the mutation-testing tool's parts share (``tools/mutate.py``): the repository root, the atomic
write it uses without importing ``ogm_ppl``, the outcome names and a short content hash."""

from __future__ import annotations

import hashlib
import importlib.util
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def _load_atomic_write_text():
    """``ogm_ppl.io.atomic_write_text``, loaded from its file (standard library only) so that this process
    still never imports the ``ogm_ppl`` package (see the module docstring)."""
    spec = importlib.util.spec_from_file_location("_ogm_ppl_io", ROOT / "ogm_ppl" / "io.py")
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod.atomic_write_text


atomic_write_text = _load_atomic_write_text()


#: see ``baselines``
RECHECK_S = 5.0

KILLED, TIMEOUT, ERROR, SURVIVED = "killed", "timeout", "error", "survived"
INCOMPETENT = "incompetent"  # not valid Python (``x & not y``): not run, left out of every count
ANNOTATION = "annotation"  # inside a type annotation: equivalent, not run (see ``annotation_spans``)
ANNOTATION_REASON = (
    "inside a type annotation, which `from __future__ import annotations` keeps as an unevaluated string"
)
DETECTED = (KILLED, TIMEOUT, ERROR)


def sha(*parts: bytes | str) -> str:
    h = hashlib.sha256()
    for p in parts:
        h.update(p.encode() if isinstance(p, str) else p)
    return h.hexdigest()[:16]
