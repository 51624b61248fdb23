"""Floor plans of the real logs' buildings, cleaned from the maps of all their readings.

``ogm-ppl study log_plans`` as a script of the checkout: the same options, output and files, defined once in
:mod:`ogm_ppl.cli._studies.maps` (``--help`` lists them).
"""

from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from ogm_ppl.cli._studies import script_main  # noqa: E402


def main(argv: list[str] | None = None) -> int:
    """``ogm-ppl study log_plans`` on ``argv``; returns the study's result (the exit status)."""
    return script_main("log_plans", argv, "log_plans.py")


if __name__ == "__main__":
    raise SystemExit(main())
