r"""The stopping score of a net-field fit that sees what mapping asks of a prior: the calibration protocol's
unseen-cell NLL on windows of the validation plans (Section 5.2.1; :mod:`ogm_ppl.calibration`).

For each of the first ``plans`` validation plans whose ``window x window`` crop (the one
:func:`~ogm_ppl.calibration.choose_window` picks) holds at least 200 known free cells, a sparse simulated scan
(:func:`~ogm_ppl.calibration.make_scene`: ``poses`` stops of ``beams`` beams, ``range_cells``, range noise
``sigma`` cells) and two single-cell Gibbs chains under the candidate field, from thresholded traditional OGM and
from the all-free map, ``sweeps`` kept after ``burn``. The score is the mean over the plans of

.. math:: -\frac{1}{|U_p|} \sum_{k \in U_p} \log_2 q_k^{m_k} (1 - q_k)^{1 - m_k},

``q`` the two chains' pooled marginals and ``U_p`` the plan's unseen near-mapped cells: a field in its ordered
phase fills them with confident walls or space and scores many bits, where the held-out pseudo-likelihood (every
neighbour known) cannot tell. The calibration protocol's third start, a prior draw, is left out: it costs 200
sweeps of the whole window a plan.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

__all__ = ["SELECT_STARTS", "SelectScenes", "selection_scenes", "unseen_nll"]

#: the starts of the scoring chains (the calibration protocol's first two)
SELECT_STARTS: tuple[str, ...] = ("ogm", "free")


@dataclass(frozen=True)
class SelectScenes:
    """The scenes a fit's candidates are scored on, and the chains' lengths."""

    scenes: tuple
    sweeps: int
    burn: int
    sigma: float
    seed: int

    @property
    def names(self) -> list[str]:
        """The scored windows' names (``plan@rROW,cCOL``)."""
        return [sc.tmap.name for sc in self.scenes]


@dataclass(frozen=True)
class _SceneOptions:
    poses: int = 3
    beams: int = 90
    range_cells: float = 75.0
    sigma: float = 1.0
    seed: int = 0


def selection_scenes(
    maps: Sequence[tuple[np.ndarray, np.ndarray]],
    names: Sequence[str],
    plans: int,
    window: int,
    sweeps: int,
    burn: int = 5,
    seed: int = 0,
    resolution: float = 0.05,
) -> SelectScenes:
    """The scenes of the first ``plans`` of the ``(occupancy, known)`` validation ``maps`` (named ``names``) with
    a usable ``window`` (module docstring); fewer when fewer are usable."""
    from ogm_ppl.calibration import make_scene
    from ogm_ppl.calibration.heldout import MIN_FREE_CELLS, TestMap, choose_window

    out = []
    for (occ, known), name in zip(maps, names):
        r0, c0 = choose_window(occ, known, window)
        h, w = min(window, occ.shape[0]), min(window, occ.shape[1])
        sl = (slice(r0, r0 + h), slice(c0, c0 + w))
        t = TestMap("validation", f"{name}@r{r0},c{c0}", name, occ[sl].copy(), known[sl].copy(), resolution)
        if (t.known & ~t.truth).sum() < MIN_FREE_CELLS:
            continue
        out.append(make_scene(t, _SceneOptions(seed=seed)))
        if len(out) == plans:
            break
    return SelectScenes(tuple(out), int(sweeps), int(burn), 1.0, int(seed))


def unseen_nll(prior_for_shape: Callable, sel: SelectScenes) -> float:
    """The mean unseen-cell NLL (bits a cell) of the field ``prior_for_shape(shape)`` over ``sel``'s scenes
    (module docstring)."""
    from ogm_ppl.calibration import score_marginals
    from ogm_ppl.inference import CellGibbs, RunningStats, run_gibbs
    from ogm_ppl.models import OccupancyModel
    from ogm_ppl.sensors import GaussianRange

    if not sel.scenes:
        raise ValueError("no validation window to score")
    scores = []
    for sc in sel.scenes:
        model = OccupancyModel(sc.grid, sc.rays, GaussianRange(sel.sigma), prior_for_shape(sc.grid.shape))
        marg = []
        for j, init in enumerate(SELECT_STARTS):
            stats = RunningStats(model)
            run_gibbs(CellGibbs(model, init=init), sel.sweeps, stats, warmup=sel.burn, seed=sel.seed + 1000 * j,
                      progress=False)  # fmt: skip
            marg.append(stats.marginals.numpy())
        q = np.clip(np.mean(marg, axis=0), 0.0, 1.0)
        scores.append(float(score_marginals(sc, q)["unseen"]["nll_bits"]))
    return float(np.mean(scores))
