"""Why the border prior trails on simulated office maps (README, Table 6.4): prior mass and likelihood of a
3 x 3 patch Gibbs chain with ``border:generated`` from the thresholded OGM start, sweep by sweep, beside the
true map's; and the true map's tiles whose (border, inner) pair the tables never counted.

    python experiments/border_chain_probe.py out/experiments/table_6_4_small sim-m1000 [--sweeps 12]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
import torch

from ogm_ppl import GaussianRange, OccupancyModel, raycast
from ogm_ppl.datasets.dataset_file import load_dataset
from ogm_ppl.inference import PatchGibbs
from ogm_ppl.priors import prior_by_name
from ogm_ppl.priors.tables import tables_by_name


def unseen_tiles(truth: np.ndarray, corpus: str = "generated") -> tuple[int, int]:
    """(tiles, tiles whose (16-cell border, 3 x 3 inner) pair is not in the corpus's border table); cells off
    the grid read as occupied, as the prior's ``outside = 1``."""
    b, i, _ = tables_by_name(corpus).border_table().triples()
    seen = set(zip(b.tolist(), i.tolist()))
    P = np.pad(truth.astype(np.int64), 2, constant_values=1)
    ring = [(r, c) for r in range(5) for c in range(5) if not (1 <= r <= 3 and 1 <= c <= 3)]
    inner = [(r, c) for r in range(1, 4) for c in range(1, 4)]
    n = unseen = 0
    for r0 in range(0, truth.shape[0] - 2, 3):
        for c0 in range(0, truth.shape[1] - 2, 3):
            W = P[r0 : r0 + 5, c0 : c0 + 5]
            key = (
                sum(int(W[r, c]) << j for j, (r, c) in enumerate(ring)),
                sum(int(W[r, c]) << k for k, (r, c) in enumerate(inner)),
            )
            n += 1
            unseen += key not in seen
    return n, unseen


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("folder", type=Path)
    ap.add_argument("dataset")
    ap.add_argument("--sweeps", type=int, default=12)
    ap.add_argument("--sigma", type=float, default=3.0)
    args = ap.parse_args()
    torch.set_default_dtype(torch.float64)
    d = load_dataset(args.folder / "datasets" / f"{args.dataset}.npz")
    assert d.grid is not None
    truth = np.load(args.folder / "datasets" / f"{args.dataset}.eval.npz")["truth"]
    prior = prior_by_name("border:generated", d.grid.shape)
    model = OccupancyModel(d.grid, raycast(d.grid, d.scans), GaussianRange(args.sigma), prior)
    n, unseen = unseen_tiles(truth)
    t = torch.from_numpy(truth.ravel().astype(np.float64))
    t[model.known_free] = 0.0
    print(
        f"true map: log prior {float(prior.log_prob(t[None])[0]):.1f}, log likelihood "
        f"{float(model.log_likelihood(t[None])[0]):.1f}; {unseen} of {n} tiles never counted"
    )
    torch.manual_seed(0)
    k = PatchGibbs(model, patch=(3, 3))
    k.setup(0)
    p = k.initial_params
    for s in range(args.sweeps):
        t0 = time.perf_counter()
        p = k.sample(p)
        m = torch.from_numpy(k.state.astype(np.float64))[None]
        print(
            f"sweep {s + 1}: log prior {float(prior.log_prob(m)[0]):.1f}, log likelihood "
            f"{float(model.log_likelihood(m)[0]):.1f}, cells unlike the truth {int((k.state != truth.ravel()).sum())}, "
            f"{time.perf_counter() - t0:.1f} s"
        )


if __name__ == "__main__":
    main()
