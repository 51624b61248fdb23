"""Where the rules of an ``active`` experiment send the robot: per-stop step lengths and coverage gains, and
the routes drawn on a plan.

``ogm-ppl study active_routes`` as a script of the checkout: the same options, output and files, defined once in
:mod:`ogm_ppl.cli._studies.active` (``--help`` lists them).
"""

from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from ogm_ppl.cli._studies import script_main  # noqa: E402


def main(argv: list[str] | None = None) -> int:
    """``ogm-ppl study active_routes`` on ``argv``; returns the study's result (the exit status)."""
    return script_main("active_routes", argv, "active_routes.py")


if __name__ == "__main__":
    raise SystemExit(main())
