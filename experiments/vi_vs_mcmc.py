"""One comparison harness: summed KL to the exact posterior against wall-clock time for
every method, on the 1D toy, on the 1000 wall datasets and on small 2D problems solved by brute force.

``ogm-ppl study vi_vs_mcmc`` as a script of the checkout (its default paths in the checkout): the same
options, output and files, defined once in :mod:`ogm_ppl.cli._studies.toys` (``--help`` lists them).
"""

from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from ogm_ppl.cli._studies import script_main  # noqa: E402


def main(argv: list[str] | None = None) -> object:
    """``ogm-ppl study vi_vs_mcmc`` on ``argv``; returns the study's result."""
    return script_main("vi_vs_mcmc", argv, "vi_vs_mcmc.py", out=str(ROOT / "out" / "vi_vs_mcmc"))


if __name__ == "__main__":
    main()
