"""Mean marginal of the never-observed cells of each map an experiment wrote, per algorithm and dataset.

``ogm-ppl study unobserved_marginals`` as a script of the checkout: the same options, output and files, defined once
in :mod:`ogm_ppl.cli._studies.maps` (``--help`` lists them).
"""

from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from ogm_ppl.cli._studies import script_main  # noqa: E402


def main(argv: list[str] | None = None) -> int:
    """``ogm-ppl study unobserved_marginals`` on ``argv``; returns the study's result (the exit status)."""
    return script_main("unobserved_marginals", argv, "unobserved_marginals.py")


if __name__ == "__main__":
    raise SystemExit(main())
