r"""Choose the prior of the headline experiment (``make run``) on training plans, never on the Intel log.

A thin front of :func:`ogm_ppl.learn.select_headline_prior` (``ogm-ppl fit-prior headline``; the protocol is in
:mod:`ogm_ppl.learn.headline`). Without ``--out`` it replaces the package's ``ogm_ppl/fitted/headline_prior.json``
(``ogm-ppl fit-prior headline --ship``).

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

from ogm_ppl.learn._heldout import split_names  # noqa: E402
from ogm_ppl.learn.headline import CANDIDATES, HeadlineSettings, select_headline_prior  # noqa: E402

__all__ = ["CANDIDATES", "main", "parse_args", "split_names"]


def parse_args(argv=None) -> argparse.Namespace:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--corpus", default="houseexpo", choices=("houseexpo", "ipa", "dungeon"))
    ap.add_argument("--plans", type=int, default=8)
    ap.add_argument("--window", type=int, default=128)
    ap.add_argument("--poses", type=int, default=4)
    ap.add_argument("--beams", type=int, default=180)
    ap.add_argument("--range-cells", type=float, default=75.0)
    ap.add_argument("--sigma", type=float, default=0.5)
    ap.add_argument("--sweeps", type=int, default=60)
    ap.add_argument("--burn", type=int, default=10)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", type=Path, default=None, help="a .json file (default ogm_ppl/fitted/headline_prior.json)")
    ap.add_argument("--quick", action="store_true")
    args = ap.parse_args(argv)
    if args.quick:
        args.plans, args.window, args.sweeps, args.burn = 2, 64, 6, 2
        args.out = args.out or ROOT / "out" / "select_headline_prior" / "headline_prior.json"
    if args.out is not None and args.out.suffix != ".json":
        ap.error(f"--out must name a .json file, got {args.out}")
    return args


def main(argv=None) -> dict:
    args = parse_args(argv)
    settings = HeadlineSettings(
        corpus=args.corpus,
        plans=args.plans,
        window=args.window,
        poses=args.poses,
        beams=args.beams,
        range_cells=args.range_cells,
        sigma=args.sigma,
        sweeps=args.sweeps,
        burn=args.burn,
        seed=args.seed,
        candidates=CANDIDATES[:2] if args.quick else CANDIDATES,
        fit_limit=10 if args.quick else None,
    )
    if args.out is None:
        r = select_headline_prior(settings=settings, ship=True)
    else:
        r = select_headline_prior(args.out.parent, settings=settings, name=args.out.stem)
    return json.loads(r.files[0].read_text())


if __name__ == "__main__":
    main()
