r"""Table 3.1 of the thesis: how far each mapping algorithm's marginals lie from the exact posterior's on 1D
problems, as the summed KL divergence over the latent cells, averaged over random datasets.

Each dataset: the robot in cell 0, ``K`` latent cells ``1..K`` (``cells``; the thesis does not state ``K``) and
a wall at cell ``f = 20``; one to eight readings (uniform), each ``round(N(20, 2^2))`` clipped to ``[0, K]``; the
Gaussian range sensor ``sigma = 2`` cells and the uniform prior ``p(m_k = 1) = 0.5``. With exact marginals
``p_k`` (:func:`~ogm_ppl.inference.exact.pose_constrained_1d`) and an algorithm's ``q_k``, the score is

.. math::

    \mathrm{KL} = \sum_{k=1}^{K} p_k \log\frac{p_k}{q_k} + (1 - p_k) \log\frac{1 - p_k}{1 - q_k}

(nats; ``q`` clamped to ``[1e-12, 1 - 1e-12]``). Rows: traditional OGM with Hähnel's update term and the
optimised terms ``p21`` and Moravec's (fitted for ``F = 75``, wall 60, ``sigma = 3`` as in Section 2.5),
online patch maps (forward sensor model) and offline patch maps (the MAP reference) with ``L = 1, 3, 5``,
offline patch maps with overlap ``L = 3, 5`` (Chapter 3), and single-cell Gibbs
(:class:`~ogm_ppl.inference.mcmc.gibbs.CellGibbs` from the OGM map; Section 4.1). Patch boundaries start
before cell 1, as in the thesis.

The study sits here, not beside the Gibbs code: it compares eleven algorithms of three chapters, Gibbs being
one row. :func:`table_3_1` runs it.
"""

from __future__ import annotations

import json
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ogm_ppl.studies._inputs import check_int, float64

__all__ = ["THESIS", "Table31Settings", "datasets", "table_3_1", "table_3_1_markdown"]

#: the thesis's mean summed KL of each row (Table 3.1)
THESIS: dict[str, float] = {
    "traditional OGM (Hähnel)": 6.7870,
    "traditional OGM, optimised (p21)": 0.2509,
    "online patch map L=1": 0.5297,
    "online patch map L=3": 0.3100,
    "online patch map L=5": 0.2290,
    "offline patch map L=1": 0.2834,
    "offline patch map L=3": 0.0749,
    "offline patch map L=5": 0.0274,
    "offline, overlap L=3": 0.0287,
    "offline, overlap L=5": 0.0038,
    "Gibbs": 3.72e-5,
}
#: the wall's cell and the range noise (cells) of every dataset
WALL, SIGMA = 20, 2.0


@dataclass(frozen=True)
class Table31Settings:
    """``datasets`` random datasets of ``cells`` latent cells drawn from ``seed``; the Gibbs row runs
    ``gibbs_sweeps`` sweeps per dataset (0 leaves the row out)."""

    datasets: int = 1000
    gibbs_sweeps: int = 100_000
    cells: int = 30
    seed: int = 0

    def checked(self) -> Table31Settings:
        """These settings, each checked (:class:`~ogm_ppl.studies.errors.StudyOptionError` names the first out of
        range)."""
        check_int(self.datasets, "datasets", 1, 10_000_000)
        check_int(self.gibbs_sweeps, "gibbs_sweeps", 0, 100_000_000)
        check_int(self.cells, "cells", WALL, 100_000)
        check_int(self.seed, "seed", 0, 2**31 - 1)
        return self


def datasets(n: int, cells: int, seed: int = 0) -> Iterator[np.ndarray]:
    """The readings (cells) of the ``n`` datasets drawn from ``seed``: one to eight each, ``round(N(20, 2^2))``
    clipped to ``[0, cells]``."""
    rng = np.random.default_rng(seed)
    for _ in range(n):
        yield np.clip(np.rint(rng.normal(float(WALL), SIGMA, int(rng.integers(1, 9)))), 0, cells)


def table_3_1(
    settings: Table31Settings | None = None, out_dir: str | Path | None = None, *, progress: bool = True
) -> dict:
    """Score every row of Table 3.1 (module docstring) on the datasets of ``settings``.

    Returns ``{"datasets", "cells", "gibbs_sweeps", "seed", "rows": {row: {"mean", "median", "thesis"}},
    "seconds"}`` (``thesis`` None for a row the thesis does not have). With ``out_dir``, also writes
    ``table_3_1.md`` (:func:`table_3_1_markdown`) and ``table_3_1.json`` (the dict) there, atomically.

    Raises:
        StudyOptionError: a setting out of range.
    """
    from ogm_ppl import GaussianRange, OccupancyModel, raycast
    from ogm_ppl.datasets import toy_1d
    from ogm_ppl.inference import evidence_grid
    from ogm_ppl.inference.exact import pose_constrained_1d
    from ogm_ppl.inference.mcmc.gibbs import CellGibbs
    from ogm_ppl.inference.patch_map import offline_patch_map, online_patch_map, reference_map
    from ogm_ppl.metrics import kl_divergence
    from ogm_ppl.models import delta_by_name
    from ogm_ppl.priors import IndependentPrior
    from ogm_ppl.progress import Progress

    s = (settings or Table31Settings()).checked()
    kls: dict[str, list[float]] = {}
    t0 = time.perf_counter()
    deltas = {
        "traditional OGM (Hähnel)": delta_by_name("haehnel"),
        "traditional OGM, optimised (p21)": delta_by_name("p21"),
        "traditional OGM, optimised (Moravec)": delta_by_name("moravec_opt"),
    }
    with float64(), Progress(s.datasets, "Table 3.1 datasets", unit="dataset", enabled=progress, after=10.0) as bar:
        for d, z in enumerate(datasets(s.datasets, s.cells, s.seed)):
            toy = toy_1d(num_cells=s.cells + 1, wall=WALL, readings=z)
            rays = raycast(toy.grid, toy.scans)
            model = OccupancyModel(toy.grid, rays, GaussianRange(SIGMA), IndependentPrior(0.5, s.cells + 1))
            exact = pose_constrained_1d(model).marginals[1:]

            def score(name, q, exact=exact):
                kls.setdefault(name, []).append(float(kl_divergence(exact, q[1:].clamp(1e-12, 1 - 1e-12))))

            for name, delta in deltas.items():
                score(name, evidence_grid(rays, delta).probabilities)
            ref = reference_map(model)
            for L in (1, 3, 5):
                score(f"online patch map L={L}", online_patch_map(model, L, offset=1).marginals)
                score(f"offline patch map L={L}", offline_patch_map(model, L, offset=1, reference=ref).marginals)
            for L in (3, 5):
                score(f"offline, overlap L={L}", offline_patch_map(model, L, overlap=True, reference=ref).marginals)
            if s.gibbs_sweeps:
                kernel = CellGibbs(model, init="ogm")
                kernel.setup()
                score("Gibbs", kernel.run_marginals(s.gibbs_sweeps, seed=s.seed * 100_003 + d))
            bar.update()
    rows = {
        k: {"mean": float(np.mean(v)), "median": float(np.median(v)), "thesis": THESIS.get(k)} for k, v in kls.items()
    }
    res = {
        "datasets": s.datasets,
        "cells": s.cells,
        "gibbs_sweeps": s.gibbs_sweeps,
        "seed": s.seed,
        "rows": rows,
        "seconds": time.perf_counter() - t0,
    }
    if out_dir is not None:
        from ogm_ppl.io import atomic_write_text

        out = Path(out_dir)
        atomic_write_text(out / "table_3_1.md", table_3_1_markdown(res))
        atomic_write_text(out / "table_3_1.json", json.dumps(res, indent=2))
    return res


def table_3_1_markdown(res: dict) -> str:
    """The table of a :func:`table_3_1` result as Markdown: each row's mean summed KL beside the thesis's."""
    lines = ["| algorithm | mean summed KL (ours) | thesis |", "|---|---|---|"]
    for k, v in res["rows"].items():
        th = "" if v["thesis"] is None else f"{v['thesis']:.4g}"
        lines.append(f"| {k} | {v['mean']:.4g} | {th} |")
    lines.append("")
    lines.append(
        f"{res['datasets']} datasets, K = {res['cells']} latent cells, Gibbs {res['gibbs_sweeps']:,} sweeps; "
        f"{res['seconds']:.0f} s."
    )
    return "\n".join(lines)
