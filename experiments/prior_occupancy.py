"""How much of a region with no readings does a prior fill? Each prior's own occupied share against its corpus's.

``ogm-ppl study prior_occupancy`` as a script of the checkout: the same options, output and files, defined once in
:mod:`ogm_ppl.cli._studies.priors` (``--help`` lists them).
"""

from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from ogm_ppl.cli._studies import script_main  # noqa: E402


def main(argv: list[str] | None = None) -> object:
    """``ogm-ppl study prior_occupancy`` on ``argv``; returns the study's result."""
    return script_main("prior_occupancy", argv, "prior_occupancy.py")


if __name__ == "__main__":
    main()
