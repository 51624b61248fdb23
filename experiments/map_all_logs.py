"""Map every shipped CARMEN log with the ``ogm-ppl map`` command and summarise times and sizes.

``ogm-ppl study map_all_logs`` as a script of the checkout (its default paths in the checkout): the same
options, output and files, defined once in :mod:`ogm_ppl.cli._studies.maps` (``--help`` lists them).
"""

from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from ogm_ppl.cli._studies import script_main  # noqa: E402


def main(argv: list[str] | None = None) -> int:
    """``ogm-ppl study map_all_logs`` on ``argv``; returns the study's result (the exit status)."""
    return script_main("map_all_logs", argv, "map_all_logs.py", data=ROOT.parent / "shared" / "data")


if __name__ == "__main__":
    raise SystemExit(main())
