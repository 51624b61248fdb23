"""What limits a corpus guide's prediction of unseen cells: its calibration, or what it can tell apart?

``ogm-ppl study guide_limits`` as a script of the checkout: the same options, output and files, defined once in
:mod:`ogm_ppl.cli._studies.guides` (``--help`` lists them).
"""

from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from ogm_ppl.cli._studies import script_main  # noqa: E402


def main(argv: list[str] | None = None) -> object:
    """``ogm-ppl study guide_limits`` on ``argv``; returns the study's result."""
    return script_main("guide_limits", argv, "guide_limits.py")


if __name__ == "__main__":
    main()
