"""Fit update terms Delta for one sensor setting (Section 2.5 at sigma, F in cells) and compare them with
the shipped ones (fitted at sigma 3, F 75, wall 60) on held-out data of that setting:
:func:`ogm_ppl.learn.fit_delta_setting` (``ogm-ppl fit-prior delta-setting``).

    python experiments/fit_delta_setting.py --sigma 1 --F 400 [--out DIR] [--names p21 moravec_opt]

Intel at 5 cm: F = 20 m / 0.05 m = 400 cells; sigma in cells = sigma_m / 0.05. Prints, per term: data and
fit seconds, train and held-out cross-entropy (mean over datasets of the summed cell cross-entropy, nats)
of the fit and of the shipped term on the same held-out data. ``--out``: write (or reuse) the fitted
terms there (``fit_delta_setting(out, reuse=True)``). ``--compare-full``: also time the fit without
the near-wall reduction.
"""

from __future__ import annotations

import argparse
import time

import torch

from ogm_ppl.datasets import wall_datasets
from ogm_ppl.inference.variational.delta_fit import cross_entropy_loss
from ogm_ppl.inference.variational.setting_fit import fit_on_data
from ogm_ppl.learn import fit_delta_setting
from ogm_ppl.models import delta_by_name
from ogm_ppl.models.delta import family_from_dict


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sigma", type=float, required=True, help="sensor noise in cells")
    ap.add_argument("--F", type=int, required=True, help="max range in cells")
    ap.add_argument("--wall", type=int, default=None, help="wall cell (default round(0.8 F))")
    ap.add_argument("--num", type=int, default=1000, help="training datasets")
    ap.add_argument("--heldout", type=int, default=500, help="held-out datasets (seed + 1)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--names", nargs="+", default=["p21", "moravec_opt"])
    ap.add_argument("--out", default=None, help="folder for the fitted terms (reused when there)")
    ap.add_argument("--threads", type=int, default=1, help="torch threads (small matrices: 1 is fastest)")
    ap.add_argument("--compare-full", action="store_true", help="also time the unreduced fit")
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    torch.optim.LBFGS(
        [torch.zeros(1, requires_grad=True)]
    )  # the first optimiser imports torch._dynamo (~5 s): not the fit's
    wall = round(0.8 * args.F) if args.wall is None else args.wall
    t0 = time.perf_counter()
    r = fit_delta_setting(
        args.out, family=args.names, sigma=args.sigma, F=args.F, wall=wall, num=args.num, seed=args.seed, reuse=True
    )
    total = time.perf_counter() - t0
    held = wall_datasets(
        num=args.heldout, F=args.F, wall=wall, sigma=args.sigma, seed=args.seed + 1
    )  # as heldout= would
    print(
        f"setting: sigma {args.sigma:g} cells, F {args.F}, wall {wall}, {args.num} training / {args.heldout} "
        f"held-out datasets; fit_delta_setting {total:.1f} s in all"
    )
    print("| term | data s (training) | fit s | train CE | held-out CE (fit) | held-out CE (shipped) |")
    print("|---|---|---|---|---|---|")
    for name, term in r.summary["terms"].items():
        tr = term["training"]
        with torch.no_grad():
            mine = float(cross_entropy_loss(family_from_dict(term["delta"]), held))
            shipped = float(cross_entropy_loss(delta_by_name(name), held))
        sec = tr.get("seconds") or {}
        print(
            f"| {name} | {sec.get('data', float('nan')):.1f} | {sec.get('fit', float('nan')):.2f} | "
            f"{tr['train_cross_entropy']:.4f} | {mine:.4f} | {shipped:.4f} |"
        )
    if args.compare_full:
        data = wall_datasets(num=args.num, F=args.F, wall=wall, sigma=args.sigma, seed=args.seed)
        for name in args.names:
            for reduce in (True, False):
                t = time.perf_counter()
                res = fit_on_data(name, data, reduce=reduce)
                print(
                    f"{name} reduce={reduce}: {time.perf_counter() - t:.2f} s, {res.iterations} iterations, "
                    f"train CE {res.train_loss:.6f}"
                )


if __name__ == "__main__":
    main()
