"""Where the pooled errors of a Table 6.4 run lie: observed or never-observed cells, and the best F1 any map
can reach without predicting never-observed free space.

``ogm-ppl study table_6_4_errors`` as a script of the checkout: the same options, output and files, defined once in
:mod:`ogm_ppl.cli._studies.maps` (``--help`` lists them).
"""

from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from ogm_ppl.cli._studies import script_main  # noqa: E402


def main(argv: list[str] | None = None) -> int:
    """``ogm-ppl study table_6_4_errors`` on ``argv``; returns the study's result (the exit status)."""
    return script_main("table_6_4_errors", argv, "table_6_4_errors.py")


if __name__ == "__main__":
    raise SystemExit(main())
