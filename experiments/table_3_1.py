"""Table 3.1: average summed KL between each mapping algorithm and the exact posterior, 1000 1D datasets.

``ogm-ppl study table_3_1`` as a script of the checkout (its default paths in the checkout): the same
options, output and files, defined once in :mod:`ogm_ppl.cli._studies.toys` (``--help`` lists them).
"""

from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from ogm_ppl.cli._studies import script_main  # noqa: E402


def main(argv: list[str] | None = None) -> object:
    """``ogm-ppl study table_3_1`` on ``argv``; returns the study's result."""
    return script_main("table_3_1", argv, "table_3_1.py", out=ROOT / "out" / "experiments")


if __name__ == "__main__":
    main()
