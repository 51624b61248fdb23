"""VI against the exact posterior on the thesis's 1D toy: summed KL of marginals and wall-clock time.

``ogm-ppl study vi_vs_exact_1d`` as a script of the checkout: the same options, output and files, defined once in
:mod:`ogm_ppl.cli._studies.toys` (``--help`` lists them).
"""

from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from ogm_ppl.cli._studies import script_main  # noqa: E402


def main(argv: list[str] | None = None) -> object:
    """``ogm-ppl study vi_vs_exact_1d`` on ``argv``; returns the study's result."""
    return script_main("vi_vs_exact_1d", argv, "vi_vs_exact_1d.py")


if __name__ == "__main__":
    main()
