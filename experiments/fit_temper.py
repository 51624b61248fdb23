r"""Fit each learned prior's tempering exponent on validation plans: the ``@cal`` of :mod:`ogm_ppl.priors.named`.

``ogm-ppl fit-prior temper`` (:func:`ogm_ppl.learn.fit_temper`; the protocol is in :mod:`ogm_ppl.learn.temper`)
with its options, every corpus by default, and without ``--out`` the package's
``ogm_ppl/fitted/temper_<corpus>.json`` replaced (``--ship``); ``--quick`` without ``--out`` writes under
``out/fit_temper``.

    python experiments/fit_temper.py --corpus houseexpo            # one corpus
    python experiments/fit_temper.py --quick --out out/fit_temper  # smoke run (2 small plans, 2 betas, 2 kinds)
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from ogm_ppl.cli._fit_kinds import add_temper, run_temper  # noqa: E402
from ogm_ppl.learn import FitOptionError  # noqa: E402


def main(argv=None) -> list[dict]:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    add_temper(ap, ship_by_default=True)
    args = ap.parse_args(argv)
    if args.out is None and not args.ship:
        args.out, args.ship = (ROOT / "out" / "fit_temper", False) if args.quick else (None, True)
    try:
        r = run_temper(args)
    except FitOptionError as e:
        ap.error(str(e))
    return [json.loads(p.read_text()) for p in r.files]


if __name__ == "__main__":
    main()
