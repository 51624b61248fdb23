"""Why the border prior trails on simulated office maps (README, Table 6.4): prior mass and likelihood of a
3 x 3 patch Gibbs chain with ``border:generated`` from the thresholded OGM start, sweep by sweep, beside the
true map's; and the true map's tiles whose (border, inner) pair the tables never counted.

``ogm-ppl study border_chain_probe`` as a script of the checkout: the same options, output and files, defined once
in :mod:`ogm_ppl.cli._studies.priors` (``--help`` lists them).
"""

from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from ogm_ppl.cli._studies import script_main  # noqa: E402


def main(argv: list[str] | None = None) -> object:
    """``ogm-ppl study border_chain_probe`` on ``argv``; returns the study's result."""
    return script_main("border_chain_probe", argv, "border_chain_probe.py")


if __name__ == "__main__":
    main()
