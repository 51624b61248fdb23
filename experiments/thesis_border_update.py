"""How far the thesis's border update (Section 5.2.3) is from the posterior it is meant to sample.

``ogm-ppl study thesis_border_update`` as a script of the checkout (its default paths in the checkout): the
same options, output and files, defined once in :mod:`ogm_ppl.cli._studies.toys` (``--help`` lists them).
"""

from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from ogm_ppl.cli._studies import script_main  # noqa: E402


def main(argv: list[str] | None = None) -> object:
    """``ogm-ppl study thesis_border_update`` on ``argv``; returns the study's result."""
    return script_main("thesis_border_update", argv, "thesis_border_update.py", out=ROOT / "out")


if __name__ == "__main__":
    main()
