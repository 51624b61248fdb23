r"""Variational inference against the exact posterior on the thesis's 1D toy: summed KL of marginals and
wall-clock time (thesis Chapter 4's variational guides on the problem of Section 3.1).

The problem: :func:`~ogm_ppl.datasets.toy_1d` with 21 cells and the thesis's readings
(:data:`~ogm_ppl.datasets.THESIS_TOY_READINGS`), :class:`~ogm_ppl.sensors.GaussianRange` with ``sigma = 3``
cells and ``p_rand = 1e-3``, the uniform :class:`~ogm_ppl.priors.IndependentPrior`. The exact marginals ``p``
come from :func:`~ogm_ppl.inference.exact.pose_constrained_1d`; every guide (mean field, patch ``L = 2``,
first hit) is fitted with every objective that applies (score-function ``TraceGraph_ELBO``,
``ReweightedWakeSleep``, the closed-form ``ExactELBO``) by :func:`~ogm_ppl.inference.variational.guides.fit_guide`,
and scored by

.. math::

    \mathrm{KL}(p \,\|\, q) = \sum_{k=1}^{20} p_k \log\frac{p_k}{q_k} + (1 - p_k) \log\frac{1 - p_k}{1 - q_k}

over the latent cells (cell 0 holds the robot; ``q`` clamped to ``[1e-9, 1 - 1e-9]``).

:func:`vi_vs_exact_1d` runs it; :func:`vi_vs_exact_1d_markdown` is its table.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from ogm_ppl.studies._inputs import check_int, float64

__all__ = ["RUNS", "vi_vs_exact_1d", "vi_vs_exact_1d_markdown"]


def _patch2(model: Any) -> Any:
    from ogm_ppl.inference.variational.guides import PatchGuide

    return PatchGuide(model, 2)


def _runs() -> list[tuple[str, Callable[[Any], Any], str, int, float, int]]:
    from ogm_ppl.inference.variational.guides import MeanFieldGuide
    from ogm_ppl.inference.variational.structured_guides import FirstHitGuide

    return [
        ("mean field", MeanFieldGuide, "tracegraph", 600, 0.1, 128),
        ("mean field", MeanFieldGuide, "rws", 600, 0.05, 256),
        ("mean field", MeanFieldGuide, "exact", 600, 0.1, 1),
        ("patch L=2", _patch2, "tracegraph", 600, 0.1, 128),
        ("patch L=2", _patch2, "rws", 600, 0.05, 256),
        ("first hit", FirstHitGuide, "tracegraph", 600, 0.1, 128),
        ("first hit", FirstHitGuide, "rws", 600, 0.05, 256),
        ("first hit", FirstHitGuide, "exact", 600, 0.1, 1),
    ]


#: the fits: (label, guide factory, loss, steps, learning rate, particles)
RUNS = _runs()
#: the file :func:`vi_vs_exact_1d` writes
FILE_NAME = "vi_vs_exact_1d.md"


def vi_vs_exact_1d(
    quick: bool = False, seed: int = 0, out_dir: str | Path | None = None, *, progress: bool = True
) -> list[tuple[str, str, int, float, float]]:
    """Fit every guide of :data:`RUNS` (``quick``: a fifth of the steps, at least 20) with ``seed`` and score it
    (module docstring).

    Returns the rows ``(guide, objective, steps, summed KL, seconds)``, the exact posterior's first (objective
    ``"-"``, KL 0). With ``out_dir``, also writes ``vi_vs_exact_1d.md`` (:func:`vi_vs_exact_1d_markdown`) there.

    Raises:
        StudyOptionError: a seed out of range.
    """
    from ogm_ppl import GaussianRange, OccupancyModel, raycast
    from ogm_ppl.datasets import THESIS_TOY_READINGS, toy_1d
    from ogm_ppl.inference.exact import pose_constrained_1d
    from ogm_ppl.inference.variational.guides import fit_guide
    from ogm_ppl.metrics import kl_divergence
    from ogm_ppl.priors import IndependentPrior
    from ogm_ppl.progress import Progress

    check_int(seed, "seed", 0, 2**31 - 1)
    rows: list[tuple[str, str, int, float, float]] = []
    with float64(), Progress(len(RUNS), "fits", unit="fit", enabled=progress, after=10.0) as bar:
        toy = toy_1d(num_cells=21, readings=THESIS_TOY_READINGS)
        model = OccupancyModel(
            toy.grid, raycast(toy.grid, toy.scans), GaussianRange(3.0, p_rand=1e-3), IndependentPrior(0.5, 21)
        )
        t = time.perf_counter()
        exact = pose_constrained_1d(model).marginals
        rows.append(("exact (pose-constrained 1D)", "-", 0, 0.0, time.perf_counter() - t))
        for label, make, loss, steps, lr, particles in RUNS:
            steps = max(steps // 5, 20) if quick else steps
            guide = make(model)
            t = time.perf_counter()
            fit_guide(model, guide, steps=steps, lr=lr, num_particles=particles, seed=seed, loss=loss)
            dt = time.perf_counter() - t
            q = guide.marginals().clamp(1e-9, 1 - 1e-9)
            kl = float(kl_divergence(exact[1:], q[1:]))  # cell 0 holds the robot: pinned free
            rows.append((label, loss, steps, kl, dt))
            bar.update(note=f"{label} {loss}: KL {kl:.2e}")
    if out_dir is not None:
        from ogm_ppl.io import atomic_write_text

        atomic_write_text(Path(out_dir) / FILE_NAME, vi_vs_exact_1d_markdown(rows, quick, seed))
    return rows


def vi_vs_exact_1d_markdown(rows: list[tuple[str, str, int, float, float]], quick: bool, seed: int) -> str:
    """The rows of :func:`vi_vs_exact_1d` as a Markdown page."""
    lines = [
        "# VI vs exact on the thesis 1D toy",
        "",
        "`toy_1d(num_cells=21, readings=THESIS_TOY_READINGS)`, `GaussianRange(3.0, p_rand=1e-3)`, "
        f"`IndependentPrior(0.5)`; seed {seed}; `ogm_ppl.studies.vi_vs_exact_1d.vi_vs_exact_1d("
        f"quick={quick}, seed={seed})`.",
        "Summed KL(exact || q) of the cell marginals over the 20 latent cells; time: wall clock of the fit.",
        "",
        "| guide | objective | steps | summed KL | time (s) |",
        "|---|---|---:|---:|---:|",
    ]
    lines += [f"| {g} | {o} | {s} | {k:.2e} | {d:.2f} |" for g, o, s, k, d in rows]
    return "\n".join(lines) + "\n"
