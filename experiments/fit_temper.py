r"""Fit each learned prior's tempering exponent on validation plans: the ``@cal`` of :mod:`ogm_ppl.priors.named`.

A thin front of :func:`ogm_ppl.learn.fit_temper` (``ogm-ppl fit-prior temper``; the protocol is in
:mod:`ogm_ppl.learn.temper`). Without ``--out`` it replaces the package's ``ogm_ppl/fitted/temper_<corpus>.json``
(``ogm-ppl fit-prior temper --ship``).

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

from ogm_ppl.learn._fit_common import CORPORA  # noqa: E402
from ogm_ppl.learn.temper import BETAS, KINDS, VALIDATION_SEED, TemperSettings, choose, fit_temper  # noqa: E402

__all__ = ["BETAS", "CORPORA", "KINDS", "VALIDATION_SEED", "choose", "main", "parse_args"]


def parse_args(argv=None) -> argparse.Namespace:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--corpus", nargs="+", default=list(CORPORA), choices=CORPORA)
    ap.add_argument("--kinds", nargs="+", default=list(KINDS))
    ap.add_argument("--betas", nargs="+", type=float, default=list(BETAS))
    ap.add_argument("--plans", type=int, default=3, help="validation plans per corpus")
    ap.add_argument("--window", type=int, default=96)
    ap.add_argument("--generated-shape", type=int, default=160)
    ap.add_argument("--poses", type=int, default=3)
    ap.add_argument("--beams", type=int, default=90)
    ap.add_argument("--range-cells", type=float, default=75.0)
    ap.add_argument("--sigma", type=float, default=1.0)
    ap.add_argument("--sweeps", type=int, default=100, help="kept sweeps per chain")
    ap.add_argument("--burn", type=int, default=25)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--max-support", type=int, default=4096)
    ap.add_argument("--kernel", default="gibbs")
    ap.add_argument("--out", type=Path, default=None, help="folder (default: the package's ogm_ppl/fitted)")
    ap.add_argument("--quick", action="store_true")
    ap.add_argument(
        "--update", action="store_true", help="keep the other kinds of an existing file; refit only --kinds"
    )
    args = ap.parse_args(argv)
    if args.quick:
        args.plans, args.window, args.sweeps, args.burn = 2, 48, 10, 4
        args.betas, args.kinds = args.betas[:2], args.kinds[:2]
        args.corpus = args.corpus[:1] if len(args.corpus) < len(CORPORA) else ["dungeon"]
        args.out = args.out or ROOT / "out" / "fit_temper"
    return args


def main(argv=None) -> list[dict]:
    args = parse_args(argv)
    settings = TemperSettings(
        kinds=tuple(args.kinds),
        betas=tuple(args.betas),
        plans=args.plans,
        window=args.window,
        generated_shape=args.generated_shape,
        poses=args.poses,
        beams=args.beams,
        range_cells=args.range_cells,
        sigma=args.sigma,
        sweeps=args.sweeps,
        burn=args.burn,
        seed=args.seed,
        max_support=args.max_support,
        kernel=args.kernel,
        fit_limit=10 if args.quick else None,
    )
    r = fit_temper(args.corpus, args.out, settings=settings, update=args.update, ship=args.out is None)
    return [json.loads(p.read_text()) for p in r.files]


if __name__ == "__main__":
    main()
