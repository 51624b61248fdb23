"""Train the amortised guide q(m | z) of a learned prior by inference compilation (Le et al. 2017):
:func:`ogm_ppl.learn.train_prior_guide` (the scenes, the loss and the held-out loss are in
:mod:`ogm_ppl.learn.prior_guide`).

    python experiments/train_amortised_guide.py            # 4-7 min on 2 shared cores; writes the shipped artefact
    python experiments/train_amortised_guide.py --steps 50 --out /tmp/g.npz    # a smoke run

Writes ``ogm_ppl/fitted/guide_amortised.npz`` and ``guide_amortised.json`` (settings, held-out loss, time).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from ogm_ppl.inference.variational.amortised import SHIPPED_GUIDE
from ogm_ppl.learn import PriorGuideSettings, train_prior_guide
from ogm_ppl.provenance import command_line


def main(argv=None) -> dict:
    """The command line; returns the sidecar's record."""
    d = PriorGuideSettings()
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--prior", default=d.prior)
    ap.add_argument("--steps", type=int, default=d.steps)
    ap.add_argument("--batch", type=int, default=d.batch)
    ap.add_argument("--lr", type=float, default=d.lr)
    ap.add_argument("--channels", type=int, default=d.channels)
    ap.add_argument("--dilations", default=",".join(map(str, d.dilations)))
    ap.add_argument("--min-size", type=int, default=d.min_size)
    ap.add_argument("--max-size", type=int, default=d.max_size)
    ap.add_argument("--max-poses", type=int, default=d.max_poses)
    ap.add_argument("--beams", type=int, default=d.beams)
    ap.add_argument("--range-cells", type=float, default=d.range_cells)
    ap.add_argument("--sigma", type=float, default=d.sigma)
    ap.add_argument("--val-scenes", type=int, default=d.val_scenes)
    ap.add_argument("--seed", type=int, default=d.seed)
    ap.add_argument("--out", default=str(SHIPPED_GUIDE))
    ap.add_argument("--threads", type=int, default=d.threads)
    args = ap.parse_args(argv)
    opts = {k: v for k, v in vars(args).items() if k != "out"}
    try:
        opts["dilations"] = tuple(int(x) for x in args.dilations.split(","))
        settings = PriorGuideSettings(**opts)
    except ValueError as e:
        raise SystemExit(f"train_amortised_guide.py: error: {e}") from None
    r = train_prior_guide(settings, args.out, command=command_line())
    print(json.dumps(r.record["heldout"], indent=1))
    return r.record


if __name__ == "__main__":
    main()
