r"""Choose the prior of the headline experiment (``make run``) on training plans, never on the Intel log.

``ogm-ppl fit-prior headline`` (:func:`ogm_ppl.learn.select_headline_prior`; the protocol is in
:mod:`ogm_ppl.learn.headline`) with its options; without ``--out`` it replaces the package's
``ogm_ppl/fitted/headline_prior.json`` (``--ship``), and ``--quick`` without ``--out`` writes under
``out/select_headline_prior``.

    python experiments/select_headline_prior.py            # -> ogm_ppl/fitted/headline_prior.json
    python experiments/select_headline_prior.py --quick    # tiny: 2 plans, 2 candidates, under out/ only
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from ogm_ppl.cli._fit_kinds import add_headline, run_headline  # noqa: E402
from ogm_ppl.learn import FitOptionError  # noqa: E402


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    add_headline(ap, ship_by_default=True)
    args = ap.parse_args(argv)
    if args.out is None and not args.ship:
        args.out, args.ship = (ROOT / "out" / "select_headline_prior", False) if args.quick else (None, True)
    try:
        r = run_headline(args)
    except FitOptionError as e:
        ap.error(str(e))
    return json.loads(r.files[0].read_text())


if __name__ == "__main__":
    main()
