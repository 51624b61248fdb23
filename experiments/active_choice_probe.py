"""What the information-gain rule trades away: at every stop of a ``sample_info`` run, the candidates' information
gain beside their expected newly observed cells, both over the same posterior samples.

``ogm-ppl study active_choice_probe`` as a script of the checkout: the same options, output and files, defined once
in :mod:`ogm_ppl.cli._studies.active` (``--help`` lists them).
"""

from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from ogm_ppl.cli._studies import script_main  # noqa: E402


def main(argv: list[str] | None = None) -> int:
    """``ogm-ppl study active_choice_probe`` on ``argv``; returns the study's result (the exit status)."""
    return script_main("active_choice_probe", argv, "active_choice_probe.py")


if __name__ == "__main__":
    raise SystemExit(main())
