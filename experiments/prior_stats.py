"""Report the thesis's patch statistics of the prior tables per corpus (Section 5.2.2-5.2.3).

``ogm-ppl study prior_stats`` as a script of the checkout (its default paths in the checkout): the same
options, output and files, defined once in :mod:`ogm_ppl.cli._studies.priors` (``--help`` lists them).
"""

from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from ogm_ppl.cli._studies import script_main  # noqa: E402


def main(argv: list[str] | None = None) -> object:
    """``ogm-ppl study prior_stats`` on ``argv``; returns the study's result."""
    return script_main("prior_stats", argv, "prior_stats.py", out=str(ROOT / "out" / "prior_stats"))


if __name__ == "__main__":
    main()
