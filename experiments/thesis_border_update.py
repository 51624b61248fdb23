"""How far the thesis's border update (Section 5.2.3) is from the posterior it is meant to sample.

    python experiments/thesis_border_update.py      # -> out/thesis_border_update.json (a few seconds after compiling)

The thesis draws each 3 x 3 patch from ``p(a_k | border_k) p(z | a_k, rest)``, ignoring the factors of the
neighbouring patches whose borders the patch forms (``PatchGibbs(update="thesis")``). On enumerable
problems (the 2 x 4 grid of ``ogm_ppl.testing.kernels.enumerable_2d`` with 2 x 2 tiles given their 12-cell
border; the 6-cell 1D toy of ``enumerable_1d`` with runs of 2 given their 2 border cells), with random full
tables (every configuration counted, so every chain is irreducible), this computes the exact one-sweep
matrix of that update (:mod:`ogm_ppl.testing.tile_updates`), its stationary distribution, and compares it
with the exact posterior of the tiled joint ``p(m) ~ prod_t p(inner_t | border_t)``: the largest error
of a cell marginal and the total variation distance. The exact update (``update="gibbs"``) is
checked on the same problems (its gap is at rounding level).
"""

from __future__ import annotations

import json
import platform
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402

from ogm_ppl import OccupancyModel  # noqa: E402
from ogm_ppl.inference.exact import brute_force  # noqa: E402
from ogm_ppl.inference.mcmc.gibbs import PatchGibbs  # noqa: E402
from ogm_ppl.io import atomic_write_text  # noqa: E402
from ogm_ppl.priors import BorderPatchPrior  # noqa: E402
from ogm_ppl.testing.kernels import enumerable_1d, enumerable_2d  # noqa: E402
from ogm_ppl.testing.tile_updates import marginal_gap, stationary, tile_sweep_matrix  # noqa: E402

SEEDS = range(5)


def _table(nb, ni, seed):
    rng = np.random.default_rng(seed)
    b, i = np.meshgrid(np.arange(2**nb), np.arange(2**ni), indexing="ij")
    counts = rng.integers(1, 9, b.shape).astype(float) ** 2  # uneven, all positive
    return b.ravel(), i.ravel(), counts.ravel()


def problems(seed):
    m2 = enumerable_2d()
    yield (
        "2x4 grid, 2x2 tiles | 12 border cells",
        OccupancyModel(m2.grid, m2.rays, m2.sensor, BorderPatchPrior((2, 4), *_table(12, 4, seed), inner=(2, 2))),
        (2, 2),
    )
    m1 = enumerable_1d()
    yield (
        "1D, 6 latent cells, runs of 2 | 2 border cells",
        OccupancyModel(m1.grid, m1.rays, m1.sensor, BorderPatchPrior((7,), *_table(2, 2, seed), inner=2)),
        2,
    )


def main() -> None:
    t0 = time.perf_counter()
    rows = []
    for seed in SEEDS:
        for name, model, patch in problems(seed):
            pi = brute_force(model).log_probs.softmax(0)
            out = {"problem": name, "seed": seed}
            for update in ("thesis", "gibbs"):
                P = tile_sweep_matrix(PatchGibbs(model, patch, update=update))
                gap = marginal_gap(model, stationary(P), pi)
                out[update] = gap
            rows.append(out)
            t, g = out["thesis"], out["gibbs"]
            print(
                f"{name:48s} seed {seed}: thesis update max |marginal error| {t['max_abs_marginal_error']:.4f}, "
                f"TV {t['total_variation']:.4f}   (exact update: {g['max_abs_marginal_error']:.1e}, "
                f"{g['total_variation']:.1e})",
                flush=True,
            )
    worst = {k: max(r["thesis"][k] for r in rows) for k in ("max_abs_marginal_error", "total_variation")}
    print(f"worst over {len(rows)} problems: {worst}")
    doc = {
        "what": "stationary distribution of PatchGibbs(update='thesis') vs the exact posterior of the tiled joint",
        "rows": rows,
        "worst_thesis": worst,
        "seconds": round(time.perf_counter() - t0, 1),
        "python": platform.python_version(),
        "script": "experiments/thesis_border_update.py",
    }
    path = ROOT / "out" / "thesis_border_update.json"
    atomic_write_text(path, json.dumps(doc, indent=1) + "\n")
    print(f"-> {path}")


if __name__ == "__main__":
    main()
