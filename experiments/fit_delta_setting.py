"""Fit update terms Delta for one sensor setting (Section 2.5 at sigma, F in cells) and compare them with
the shipped ones (fitted at sigma 3, F 75, wall 60) on held-out data of that setting.

The command line of :func:`ogm_ppl.studies.fit_delta_setting.delta_setting_heldout` (the fit is
:func:`ogm_ppl.learn.fit_delta_setting`, ``ogm-ppl fit-prior delta-setting``).

    python experiments/fit_delta_setting.py --sigma 1 --F 400 [--out DIR] [--names p21 moravec_opt]

Intel at 5 cm: F = 20 m / 0.05 m = 400 cells; sigma in cells = sigma_m / 0.05. Prints, per term: data and
fit seconds, train and held-out cross-entropy (mean over datasets of the summed cell cross-entropy, nats)
of the fit and of the shipped term on the same held-out data. ``--out``: write (or reuse) the fitted
terms there. ``--compare-full``: also time the fit without the near-wall reduction.
"""

from __future__ import annotations

import argparse

import torch

from ogm_ppl.learn import FitOptionError
from ogm_ppl.studies.fit_delta_setting import delta_setting_heldout, delta_setting_lines


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sigma", type=float, required=True, help="sensor noise in cells")
    ap.add_argument("--F", type=int, required=True, help="max range in cells")
    ap.add_argument("--wall", type=int, default=None, help="wall cell (default round(0.8 F))")
    ap.add_argument("--num", type=int, default=1000, help="training datasets")
    ap.add_argument("--heldout", type=int, default=500, help="held-out datasets (seed + 1)")
    ap.add_argument("--seed", type=int, default=0, help="seed of the training datasets (0)")
    ap.add_argument("--names", nargs="+", default=["p21", "moravec_opt"], help="the terms fitted")
    ap.add_argument("--out", default=None, help="folder for the fitted terms (reused when there)")
    ap.add_argument("--threads", type=int, default=1, help="torch threads (small matrices: 1 is fastest)")
    ap.add_argument("--compare-full", action="store_true", help="also time the unreduced fit")
    args = ap.parse_args(argv)
    torch.set_num_threads(args.threads)
    try:
        doc = delta_setting_heldout(
            args.sigma, args.F, wall=args.wall, num=args.num, heldout=args.heldout, seed=args.seed,
            names=args.names, out_dir=args.out, compare_full=args.compare_full,
        )  # fmt: skip
    except FitOptionError as e:
        ap.error(str(e))
    print("\n".join(delta_setting_lines(doc)))
    return doc


if __name__ == "__main__":
    main()
