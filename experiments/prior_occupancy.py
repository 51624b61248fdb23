r"""How much of a region with no readings does a prior fill? Each prior's own occupied share against its corpus's.

A prior learned from a corpus predicts a cell no ray reached from the cells around it; far from any reading its
prediction is what the prior itself holds: ``E_p[mean_k m_k]``, the occupied share of maps drawn from it. At the
maximum-likelihood fit of a joint whose sufficient statistics include the occupied share (an independent prior's
``lambda``; a pattern field's window codes) that share equals the training corpus's (moment matching). The tables
of Chapter 5 are products of tile conditionals, not normalised fits of a joint, so nothing makes theirs match.

For each prior (``--priors``, learned on each ``--train`` corpus; ``@cal`` names tempered as in
``ogm-ppl calibrate``) this runs three chains of the prior's mixing cycle
(:func:`~ogm_ppl.inference.mcmc.mixing_cycle`: the calibration protocol's sampler, ``--kernel cycle``) on a
``--window`` square with no readings (one short ray at the centre, which the model needs; its cells are not
counted), from the all-free map, the all-occupied map and a prior draw, and records the occupied share of the
window every ``--every`` sweeps. The prior's share is the mean over the second half of the three chains; the
corpus's is ``lambda`` of its tables (the learned independent prior: the occupied share of the training plans).

    python experiments/prior_occupancy.py --train dungeon houseexpo       # a few minutes

``--fit-bias`` also fits, per prior, the bias ``h`` of :class:`~ogm_ppl.priors.BiasedPrior` (the prior times
``exp(h sum_k m_k)``) whose share is the corpus's, and writes ``OUT/bias.json``, which ``ogm-ppl calibrate
--bias-file`` reads: :func:`ogm_ppl.learn.fit_bias` (``ogm-ppl fit-prior bias``; the bisection is in
:mod:`ogm_ppl.learn.bias`).

Writes ``OUT/prior_occupancy.json`` (settings, provenance, one row per prior with each chain's trace) and prints
a table.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from ogm_ppl.calibration import prior_names
from ogm_ppl.io import atomic_write_text
from ogm_ppl.learn.bias import STARTS, BiasSettings, empty_model, fit_bias, occupancy_trace
from ogm_ppl.priors.named import load_temper_params, split_prior_name
from ogm_ppl.priors.tables import tables_by_name

__all__ = ["PRIORS", "STARTS", "TRAIN", "empty_model", "main"]

TRAIN = ("generated", "houseexpo", "ipa", "dungeon")
PRIORS = ("border_bo", "border_bo@cal", "border1_bo", "border1_bo@cal", "patch3")


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--priors", nargs="+", default=list(PRIORS), help="prior kinds (KIND[@cal])")
    ap.add_argument("--train", nargs="+", default=list(TRAIN), choices=TRAIN, help="corpora the priors learned on")
    ap.add_argument("--window", type=int, default=96, help="cells a side (default 96, the calibration window)")
    ap.add_argument("--sweeps", type=int, default=1000, help="sweeps per chain (default 1000)")
    ap.add_argument("--every", type=int, default=50, help="record the occupied share every this many sweeps")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument(
        "--fit-bias",
        action="store_true",
        help="also fit each prior's bias h (BiasedPrior) to its corpus's share; writes OUT/bias.json",
    )
    ap.add_argument("--bias-range", type=float, default=2.0, help="bisection interval [-R, R] of h (default 2)")
    ap.add_argument("--bias-steps", type=int, default=7, help="bisection steps (default 7)")
    ap.add_argument("--out", type=Path, default=Path("out/prior_occupancy"))
    args = ap.parse_args(argv)
    if args.window < 4 or args.every < 1 or args.sweeps < 2 * args.every:
        raise SystemExit("--window must be at least 4, --every at least 1 and --sweeps at least 2 x --every")
    if not (args.bias_range > 0 and args.bias_steps >= 1):
        raise SystemExit("--bias-range must be positive and --bias-steps at least 1")
    for k in args.priors:
        kind, corpus, _, _ = split_prior_name(k)
        if corpus:
            raise SystemExit(f"--priors takes kinds (the corpora are --train), got {k!r}")
    from ogm_ppl.provenance import provenance

    settings = BiasSettings(args.window, args.sweeps, args.every, args.seed, args.bias_range, args.bias_steps)
    fits = {}
    if args.fit_bias:
        r = fit_bias(args.priors, args.out, train=args.train, settings=settings, progress=False)
        fits = json.loads(r.files[0].read_text())["fits"]
    t0 = time.perf_counter()
    rows: list[dict] = []
    print(f"occupied share of an empty {args.window} x {args.window} window, second half of 3 chains")
    print(f"{'prior':28s} {'corpus':>7s} {'prior':>6s}  chains (free, occupied, prior start)")
    for corpus in args.train:
        lam = float(tables_by_name(corpus).lam)
        for kind in args.priors:
            base, _, _, mod = split_prior_name(kind)
            name = prior_names([kind], [corpus])[-1][0]  # KIND:CORPUS[@MOD]
            if mod == "cal" and base not in load_temper_params(corpus).beta:
                print(f"{name:28s} skipped: no tempering exponent fitted")
                continue
            r = occupancy_trace(name, settings)
            rows.append({"prior": name, "kind": kind, "train": corpus, "corpus_share": lam, **r})
            chains = " ".join(f"{v:.3f}" for v in r["chain_shares"])
            print(f"{name:28s} {lam:7.3f} {r['share']:6.3f}  {chains}  ({r['seconds']:.0f} s)", flush=True)
            if args.fit_bias:
                f = {k: v for k, v in fits[name].items() if k not in ("kind", "train", "corpus_share")}
                rows[-1]["fit"] = f
                chains = " ".join(f"{v:.3f}" for v in f["chain_shares"])
                print(
                    f"{'  biased, h = ' + format(f['bias'], '+.3f'):28s} {lam:7.3f} {f['share']:6.3f}  {chains}",
                    flush=True,
                )
    doc = {
        "provenance": provenance(),
        "settings": {
            k: getattr(args, k)
            for k in ("priors", "train", "window", "sweeps", "every", "seed", "fit_bias", "bias_range", "bias_steps")
        },
        "starts": list(STARTS),
        "rows": rows,
        "seconds": time.perf_counter() - t0,
    }
    args.out.mkdir(parents=True, exist_ok=True)
    path = args.out / "prior_occupancy.json"
    atomic_write_text(path, json.dumps(doc, indent=1, allow_nan=False))
    print(f"wrote {path} ({doc['seconds']:.0f} s)")
    return doc


if __name__ == "__main__":
    main()
