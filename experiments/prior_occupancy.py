r"""How much of a region with no readings does a prior fill? Each prior's own occupied share against its corpus's.

The command line of :func:`ogm_ppl.studies.prior_occupancy.prior_occupancy` (the chains, the shares and the
moment-matching argument are in :mod:`ogm_ppl.studies.prior_occupancy`). ``--fit-bias`` also fits each
prior's bias ``h`` (:func:`ogm_ppl.learn.fit_bias`, ``ogm-ppl fit-prior bias``) and writes ``OUT/bias.json``,
which ``ogm-ppl calibrate --bias-file`` reads.

    python experiments/prior_occupancy.py --train dungeon houseexpo       # a few minutes

Writes ``OUT/prior_occupancy.json`` (settings, provenance, one row per prior with each chain's trace) and prints
a table.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from ogm_ppl.learn import FitOptionError
from ogm_ppl.learn.bias import BiasSettings
from ogm_ppl.studies.errors import STUDY_ERRORS
from ogm_ppl.studies.prior_occupancy import PRIORS, TRAIN, prior_occupancy, prior_occupancy_lines


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--priors", nargs="+", default=list(PRIORS), help="prior kinds (KIND[@cal])")
    ap.add_argument("--train", nargs="+", default=list(TRAIN), choices=TRAIN, help="corpora the priors learned on")
    ap.add_argument("--window", type=int, default=96, help="cells a side (default 96, the calibration window)")
    ap.add_argument("--sweeps", type=int, default=1000, help="sweeps per chain (default 1000)")
    ap.add_argument("--every", type=int, default=50, help="record the occupied share every this many sweeps")
    ap.add_argument("--seed", type=int, default=0, help="seed of the chains (0)")
    ap.add_argument(
        "--fit-bias",
        action="store_true",
        help="also fit each prior's bias h (BiasedPrior) to its corpus's share; writes OUT/bias.json",
    )
    ap.add_argument("--bias-range", type=float, default=2.0, help="bisection interval [-R, R] of h (default 2)")
    ap.add_argument("--bias-steps", type=int, default=7, help="bisection steps (default 7)")
    ap.add_argument("--out", type=Path, default=Path("out/prior_occupancy"), help="the output folder")
    args = ap.parse_args(argv)
    settings = BiasSettings(args.window, args.sweeps, args.every, args.seed, args.bias_range, args.bias_steps)
    try:
        doc = prior_occupancy(args.priors, args.train, settings, args.out, fit_bias=args.fit_bias)
    except (FitOptionError, *STUDY_ERRORS) as e:
        ap.error(str(e))
    print("\n".join(prior_occupancy_lines(doc)))
    print(f"wrote {args.out / 'prior_occupancy.json'} ({doc['seconds']:.0f} s)")
    return doc


if __name__ == "__main__":
    main()
