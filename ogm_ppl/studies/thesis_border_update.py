r"""How far the thesis's border update (Section 5.2.3) is from the posterior it is meant to sample.

The thesis draws each 3 x 3 patch from ``p(a_k | border_k) p(z | a_k, rest)``, ignoring the factors of the
neighbouring patches whose borders the patch forms (``PatchGibbs(update="thesis")``). The tiled joint it means to
sample is

.. math::

    p(m \mid z) \propto p(z \mid m) \prod_t p(\mathrm{inner}_t \mid \mathrm{border}_t).

On enumerable problems (the 2 x 4 grid of :func:`~ogm_ppl.testing.kernels.enumerable_2d` with 2 x 2 tiles given
their 12-cell border; the 6-cell 1D toy of :func:`~ogm_ppl.testing.kernels.enumerable_1d` with runs of 2 given
their 2 border cells), with random full tables (every configuration counted, so every chain is irreducible),
:func:`thesis_border_update` computes the exact one-sweep matrix ``P`` of that update
(:mod:`ogm_ppl.testing.tile_updates`), its stationary distribution ``pi P = pi``, and compares it with the exact
posterior of the tiled joint: the largest error of a cell marginal and the total variation distance. The exact
update (``update="gibbs"``) is checked on the same problems (its gap is at rounding level).
"""

from __future__ import annotations

import json
import platform
import time
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["SEEDS", "problems", "thesis_border_update", "thesis_border_update_lines"]

#: the seeds of the random tables
SEEDS = range(5)
#: the file :func:`thesis_border_update` writes
FILE_NAME = "thesis_border_update.json"


def _table(nb: int, ni: int, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Every (border, inner) pair of ``nb`` border and ``ni`` inner cells, counted ``c^2`` times with ``c``
    uniform in 1..8 (uneven, all positive)."""
    rng = np.random.default_rng(seed)
    b, i = np.meshgrid(np.arange(2**nb), np.arange(2**ni), indexing="ij")
    counts = rng.integers(1, 9, b.shape).astype(float) ** 2
    return b.ravel(), i.ravel(), counts.ravel()


def problems(seed: int) -> Iterator[tuple[str, Any, Any]]:
    """The two problems of ``seed``: ``(name, model, patch)``."""
    from ogm_ppl import OccupancyModel
    from ogm_ppl.priors import BorderPatchPrior
    from ogm_ppl.testing.kernels import enumerable_1d, enumerable_2d

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


def thesis_border_update(
    seeds: Iterable[int] = SEEDS, out_dir: str | Path | None = None, *, progress: bool = True
) -> dict:
    """The gap of each update on each problem of each seed (module docstring).

    Returns ``{"what", "rows": [{"problem", "seed", "thesis": gap, "gibbs": gap}], "worst_thesis", "seconds",
    "python", "script"}``, each gap ``{"max_abs_marginal_error", "total_variation"}``
    (:func:`~ogm_ppl.testing.tile_updates.marginal_gap`). With ``out_dir``, also writes
    ``thesis_border_update.json`` (the dict) there.
    """
    from ogm_ppl.inference.exact import brute_force
    from ogm_ppl.inference.mcmc.gibbs import PatchGibbs
    from ogm_ppl.progress import Progress
    from ogm_ppl.testing.tile_updates import marginal_gap, stationary, tile_sweep_matrix

    seeds = list(seeds)
    t0 = time.perf_counter()
    rows = []
    with Progress(2 * len(seeds), "problems", unit="problem", enabled=progress, after=10.0) as bar:
        for seed in seeds:
            for name, model, patch in problems(seed):
                pi = brute_force(model).log_probs.softmax(0)
                out: dict[str, Any] = {"problem": name, "seed": seed}
                for update in ("thesis", "gibbs"):
                    P = tile_sweep_matrix(PatchGibbs(model, patch, update=update))
                    out[update] = marginal_gap(model, stationary(P), pi)
                rows.append(out)
                bar.update(note=f"{name}, seed {seed}")
    worst = {k: max(r["thesis"][k] for r in rows) for k in ("max_abs_marginal_error", "total_variation")}
    doc = {
        "what": "stationary distribution of PatchGibbs(update='thesis') vs the exact posterior of the tiled joint",
        "rows": rows,
        "worst_thesis": worst,
        "seconds": round(time.perf_counter() - t0, 1),
        "python": platform.python_version(),
        "function": "ogm_ppl.studies.thesis_border_update.thesis_border_update",
    }
    if out_dir is not None:
        from ogm_ppl.io import atomic_write_text

        atomic_write_text(Path(out_dir) / FILE_NAME, json.dumps(doc, indent=1) + "\n")
    return doc


def thesis_border_update_lines(doc: dict) -> list[str]:
    """A :func:`thesis_border_update` result as lines: each problem's gaps, then the worst of the thesis's."""
    lines = []
    for r in doc["rows"]:
        t, g = r["thesis"], r["gibbs"]
        lines.append(
            f"{r['problem']:48s} seed {r['seed']}: thesis update max |marginal error| "
            f"{t['max_abs_marginal_error']:.4f}, "
            f"TV {t['total_variation']:.4f}   (exact update: {g['max_abs_marginal_error']:.1e}, "
            f"{g['total_variation']:.1e})"
        )
    lines.append(f"worst over {len(doc['rows'])} problems: {doc['worst_thesis']}")
    return lines
