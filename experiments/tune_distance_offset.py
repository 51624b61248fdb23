"""Choose the distance offset ``d_0`` of the per-metre exploration rules on *validation* plans, never on the
held-out plans the ``active`` experiments score.

``ogm-ppl study tune_distance_offset`` as a script of the checkout: the same options, output and files, defined once
in :mod:`ogm_ppl.cli._studies.active` (``--help`` lists them).
"""

from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from ogm_ppl.cli._studies import script_main  # noqa: E402


def main(argv: list[str] | None = None) -> int:
    """``ogm-ppl study tune_distance_offset`` on ``argv``; returns the study's result (the exit status)."""
    return script_main("tune_distance_offset", argv, "tune_distance_offset.py")


if __name__ == "__main__":
    raise SystemExit(main())
