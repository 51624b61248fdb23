"""Where maps' errors on the touched cells of an experiment lie, against the benchmark's walls.

``ogm-ppl study touched_errors`` as a script of the checkout: the same options, output and files, defined once in
:mod:`ogm_ppl.cli._studies.maps` (``--help`` lists them).
"""

from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from ogm_ppl.cli._studies import script_main  # noqa: E402


def main(argv: list[str] | None = None) -> object:
    """``ogm-ppl study touched_errors`` on ``argv``; returns the study's result."""
    return script_main("touched_errors", argv, "touched_errors.py")


if __name__ == "__main__":
    main()
