"""Fit update terms Delta for one sensor setting (Section 2.5 at sigma, F in cells) and compare them with
the shipped ones (fitted at sigma 3, F 75, wall 60) on held-out data of that setting.

``ogm-ppl study fit_delta_setting`` as a script of the checkout: the same options, output and files, defined once in
:mod:`ogm_ppl.cli._studies.toys` (``--help`` lists them).
"""

from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from ogm_ppl.cli._studies import script_main  # noqa: E402


def main(argv: list[str] | None = None) -> object:
    """``ogm-ppl study fit_delta_setting`` on ``argv``; returns the study's result."""
    return script_main("fit_delta_setting", argv, "fit_delta_setting.py")


if __name__ == "__main__":
    main()
