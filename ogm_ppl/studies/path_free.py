r"""Is a path free? The exact joint answer against the product of marginals, and both against the truth.

A robot that plans through cells it has not seen needs :math:`P(\text{path free} \mid z)`, the probability
that *every* cell of the path is free. From per-cell marginals alone (a guide, traditional OGM) the only
answer is the product

.. math::

    \hat P_\perp(W) = \prod_{c \in W} \bigl(1 - p(m_c = 1 \mid z)\bigr),

which assumes the cells independent given the readings. Under a prior with cell correlations (thesis
Chapters 4-5) the posterior's answer is the joint one,

.. math::

    P(W) = \sum_{m} p(m \mid z) \prod_{c \in W} [m_c = 0],

which differs from the product by the cells' dependence: free cells come in runs (a corridor, a room's
interior), so for a path along them :math:`P(W) > \hat P_\perp(W)`, and the product is the more wrong the
longer the path (:func:`~ogm_ppl.exploration.path_free_probability` computes either from samples or from
marginals; :meth:`~ogm_ppl.posterior.MapPosterior.prob_free` and ``prob_free_independent`` on a posterior).

:func:`path_free` measures both on *enumerable* scenes cut from held-out floor plans, where :math:`P(W)` is
exact (:func:`~ogm_ppl.inference.exact.brute_force` over all :math:`2^L` maps of the window's latent cells):

* a scene is a ``rows x cols`` window of a held-out plan of ``corpus`` (its cells all known, both free and
  occupied cells in it), a robot at a random free cell, ``beams`` beams of ``range_cells`` (Gaussian range
  noise ``sigma`` cells, :func:`~ogm_ppl.datasets.simulate.simulate_scans`), so part of the window is seen and
  part is not;
* the paths are the window's straight runs of 2 or more cells (rows and columns) holding at least one cell no
  ray reached;
* for each prior, the scene's exact posterior gives :math:`P(W)` and the marginals give
  :math:`\hat P_\perp(W)`; the plan says whether the path is free.

Reported per prior: the error of the product against the exact answer (mean and largest
:math:`|\hat P_\perp - P|`, the mean :math:`\log_2(\hat P_\perp / P)`, the share of paths it underrates), by path
length; and the log loss (bits per path) and Brier score of each answer against the truth, with a reliability
table. The same posterior gives both answers, so the difference is the independence assumption alone; the
truth tells how much it costs a planner.
"""

from __future__ import annotations

import json
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import torch

from ogm_ppl.studies._inputs import check_int, check_positive, float64
from ogm_ppl.studies.errors import StudyOptionError

__all__ = ["FILE_NAME", "PathFreeSettings", "path_free", "path_free_lines", "straight_paths"]

#: the file :func:`path_free` writes
FILE_NAME = "path_free.json"
#: the priors scored by default: the uniform prior with the corpus's occupied share, the 3 x 3 patch table and
#: the two-scale pattern field, each learned on HouseExpo's training plans
PRIORS: tuple[str, ...] = ("independent:houseexpo", "patch3:houseexpo", "field2:houseexpo")
#: the largest window: 2^24 maps of its latent cells (the exact posterior's limit)
MAX_CELLS = 24
#: predicted probabilities are clipped to [EPS, 1 - EPS] before the log loss
EPS = 1e-6


@dataclass(frozen=True)
class PathFreeSettings:
    """The scenes and priors of :func:`path_free` (module docstring)."""

    corpus: str = "houseexpo"
    priors: tuple[str, ...] = PRIORS
    scenes: int = 60
    rows: int = 4
    cols: int = 4
    beams: int = 8
    range_cells: float = 2.5
    sigma: float = 0.5
    seed: int = 0
    #: held-out plans the scenes are cut from (each plan gives at most ``scenes_per_plan``)
    plans: int = 30
    scenes_per_plan: int = 2

    def check(self) -> PathFreeSettings:
        """These settings, each checked (:class:`StudyOptionError` names the first out of range)."""
        check_int(self.scenes, "scenes", 1, 10_000)
        check_int(self.rows, "rows", 1, MAX_CELLS)
        check_int(self.cols, "cols", 2, MAX_CELLS)
        if self.rows * self.cols > MAX_CELLS:
            raise StudyOptionError("rows", f"rows x cols = {self.rows * self.cols} cells; the limit is {MAX_CELLS}")
        check_int(self.beams, "beams", 1, 360)
        check_positive(self.range_cells, "range_cells")
        check_positive(self.sigma, "sigma")
        check_int(self.seed, "seed", 0)
        check_int(self.plans, "plans", 1)
        check_int(self.scenes_per_plan, "scenes_per_plan", 1)
        if not self.priors:
            raise StudyOptionError("priors", "name at least one prior")
        return self


def straight_paths(rows: int, cols: int, min_length: int = 2) -> list[np.ndarray]:
    """Every straight run of ``min_length`` or more cells along a row or a column of a ``rows x cols`` grid,
    as flat (row-major) cell indices in order along the run."""
    out: list[np.ndarray] = []
    idx = np.arange(rows * cols).reshape(rows, cols)
    for line in [*idx, *idx.T]:
        n = len(line)
        for a in range(n):
            for b in range(a + min_length, n + 1):
                out.append(line[a:b].copy())
    return out


def _scenes(s: PathFreeSettings, rng: np.random.Generator) -> list[dict]:
    """Enumerable windows of held-out plans: truth, a robot pose in a free cell, the plan's name."""
    from ogm_ppl.calibration.heldout import heldout_maps

    maps = heldout_maps(s.corpus, s.plans, window=max(48, 4 * max(s.rows, s.cols)))
    if not maps:
        raise StudyOptionError("corpus", f"{s.corpus} has no held-out plan with a usable window")
    out: list[dict] = []
    for t in maps:
        H, W = t.truth.shape
        tries = 0
        got = 0
        while got < s.scenes_per_plan and tries < 400 and len(out) < s.scenes:
            tries += 1
            r, c = int(rng.integers(0, H - s.rows + 1)), int(rng.integers(0, W - s.cols + 1))
            truth = t.truth[r : r + s.rows, c : c + s.cols]
            if not t.known[r : r + s.rows, c : c + s.cols].all() or truth.all() or not truth.any():
                continue
            free = np.flatnonzero(~truth.ravel())
            cell = int(rng.choice(free))
            out.append({"plan": t.name, "corner": [r, c], "truth": truth.copy(), "robot": cell})
            got += 1
        if len(out) == s.scenes:
            break
    return out


def _exact_answers(post, latent: np.ndarray, paths: Sequence[np.ndarray]) -> np.ndarray:
    """``P(every cell of the path free | z)`` of each path from a brute-force posterior: the summed
    probability of the maps whose latent cells on the path are all 0 (pinned cells are free in every map)."""
    L = len(latent)
    pos = -np.ones(int(post.model.num_cells), dtype=np.int64)
    pos[latent] = np.arange(L)
    probs = torch.exp(post.log_probs)
    codes = torch.arange(1 << L, dtype=torch.int64)
    out = np.empty(len(paths))
    for i, p in enumerate(paths):
        bits = pos[p]
        mask = int(sum(1 << int(b) for b in bits if b >= 0))
        out[i] = float(probs[(codes & mask) == 0].sum())
    return out


def path_free(
    settings: PathFreeSettings | None = None,
    out_dir: str | Path | None = None,
    *,
    command: str | None = None,
    progress: bool = True,
) -> dict:
    """The exact and the independent ``P(path free)`` of every straight path of enumerable held-out scenes,
    under each prior, against the plans' truth (module docstring).

    Args:
        settings: the scenes and priors (:class:`PathFreeSettings`; default the module's defaults).
        out_dir: where ``path_free.json`` goes (written atomically); None writes nothing.
        command: the command line recorded in the provenance.

    Returns:
        A dict with ``settings``, ``provenance``, ``seconds``, ``scenes``, ``summary`` (per prior),
        ``by_length`` (per prior, one row a path length) and ``paths`` (each: ``scene``, ``prior``, ``length``,
        ``exact``, ``independent``, ``truth_free``).

    Raises:
        StudyOptionError: a setting out of range or a prior name that is not one.
    """
    from ogm_ppl import GaussianRange, Grid, OccupancyModel, raycast
    from ogm_ppl.datasets.simulate import simulate_scans
    from ogm_ppl.inference.exact import brute_force
    from ogm_ppl.io import atomic_write_text
    from ogm_ppl.priors import prior_by_name
    from ogm_ppl.provenance import provenance

    s = (settings or PathFreeSettings()).check()
    t0 = time.perf_counter()
    priors = {}
    for name in s.priors:
        try:
            priors[name] = prior_by_name(name, (s.rows, s.cols))
        except (KeyError, ValueError) as e:
            raise StudyOptionError("priors", f"{name!r}: {e}") from None
    rng = np.random.default_rng(s.seed)
    scenes = _scenes(s, rng)
    paths = straight_paths(s.rows, s.cols)
    angles = np.linspace(-np.pi, np.pi, s.beams, endpoint=False)
    rows: list[dict] = []
    with float64():
        for k, sc in enumerate(scenes):
            grid = Grid((s.rows, s.cols), resolution=1.0)
            r, c = divmod(sc["robot"], s.cols)
            pose = np.array([[c + 0.5, r + 0.5, float(rng.uniform(-np.pi, np.pi))]])
            scans = simulate_scans(grid, sc["truth"], pose, angles, s.range_cells, s.sigma, seed=rng)
            rays = raycast(grid, scans)
            reached = np.zeros(grid.num_cells, dtype=bool)
            reached[rays.cells] = True
            truth = sc["truth"].ravel()
            for name, prior in priors.items():
                model = OccupancyModel(grid, rays, GaussianRange(s.sigma), prior)
                post = brute_force(model, max_cells=MAX_CELLS)
                latent = np.asarray(model.latent, dtype=np.int64)
                q = post.marginals.numpy()
                chosen = [p for p in paths if not reached[p].all()]
                exact = _exact_answers(post, latent, chosen)
                for p, pe in zip(chosen, exact, strict=True):
                    rows.append(
                        {
                            "scene": k,
                            "prior": name,
                            "length": len(p),
                            "exact": float(pe),
                            "independent": float(np.prod(1.0 - q[p])),
                            "truth_free": bool(not truth[p].any()),
                        }
                    )
            if progress:
                print(f"path-free: scene {k + 1}/{len(scenes)} ({time.perf_counter() - t0:.0f} s)", flush=True)
    doc = {
        "settings": {**asdict(s), "priors": list(s.priors)},
        "provenance": provenance(command),
        "seconds": time.perf_counter() - t0,
        "scenes": [{"plan": sc["plan"], "corner": sc["corner"], "robot": sc["robot"]} for sc in scenes],
        "summary": {n: _summary([r for r in rows if r["prior"] == n]) for n in s.priors},
        "by_length": {n: _by_length([r for r in rows if r["prior"] == n]) for n in s.priors},
        "paths": rows,
    }
    if out_dir is not None:
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        atomic_write_text(out / FILE_NAME, json.dumps(doc, indent=1) + "\n")
    return doc


def _log_loss_bits(p: np.ndarray, y: np.ndarray) -> float:
    p = np.clip(p, EPS, 1 - EPS)
    return float(-np.mean(np.where(y, np.log2(p), np.log2(1 - p))))


def _reliability(p: np.ndarray, y: np.ndarray, bins: int = 5) -> list[dict]:
    edges = np.linspace(0.0, 1.0, bins + 1)
    which = np.clip(np.digitize(p, edges[1:-1]), 0, bins - 1)
    out = []
    for b in range(bins):
        sel = which == b
        if sel.any():
            out.append(
                {"bin": [float(edges[b]), float(edges[b + 1])], "n": int(sel.sum()),
                 "predicted": float(p[sel].mean()), "observed": float(y[sel].mean())}
            )  # fmt: skip
    return out


def _summary(rows: list[dict]) -> dict:
    """The product's error against the exact answer, and each answer's scores against the truth."""
    if not rows:
        return {"paths": 0}
    pe = np.array([r["exact"] for r in rows])
    pi = np.array([r["independent"] for r in rows])
    y = np.array([r["truth_free"] for r in rows])
    err = pi - pe
    return {
        "paths": len(rows),
        "truth_free_share": float(y.mean()),
        "independent_minus_exact_mean_abs": float(np.abs(err).mean()),
        "independent_minus_exact_max_abs": float(np.abs(err).max()),
        "independent_log2_ratio_mean": float(np.mean(np.log2(np.maximum(pi, EPS) / np.maximum(pe, EPS)))),
        "independent_underrates_share": float((err < -1e-12).mean()),
        "log_loss_bits": {"exact": _log_loss_bits(pe, y), "independent": _log_loss_bits(pi, y)},
        "brier": {"exact": float(np.mean((pe - y) ** 2)), "independent": float(np.mean((pi - y) ** 2))},
        "reliability": {"exact": _reliability(pe, y), "independent": _reliability(pi, y)},
    }


def _by_length(rows: list[dict]) -> list[dict]:
    out = []
    for n in sorted({r["length"] for r in rows}):
        sub = [r for r in rows if r["length"] == n]
        pe = np.array([r["exact"] for r in sub])
        pi = np.array([r["independent"] for r in sub])
        y = np.array([r["truth_free"] for r in sub])
        out.append(
            {
                "length": n,
                "paths": len(sub),
                "exact_mean": float(pe.mean()),
                "independent_mean": float(pi.mean()),
                "truth_free_share": float(y.mean()),
                "mean_abs_error": float(np.abs(pi - pe).mean()),
                "log_loss_bits_exact": _log_loss_bits(pe, y),
                "log_loss_bits_independent": _log_loss_bits(pi, y),
            }
        )
    return out


def path_free_lines(doc: dict) -> list[str]:
    """A plain-text table of :func:`path_free`'s summary, one line per prior."""
    lines = [
        f"{'prior':<26} {'paths':>6} {'|ind-exact|':>11} {'max':>6} {'log2 ratio':>10} "
        f"{'bits exact':>10} {'bits ind':>9} {'Brier ex':>9} {'Brier ind':>9}"
    ]
    for name, r in doc["summary"].items():
        if not r.get("paths"):
            lines.append(f"{name:<26} {0:>6}")
            continue
        lines.append(
            f"{name:<26} {r['paths']:>6} {r['independent_minus_exact_mean_abs']:>11.4f} "
            f"{r['independent_minus_exact_max_abs']:>6.3f} {r['independent_log2_ratio_mean']:>10.3f} "
            f"{r['log_loss_bits']['exact']:>10.4f} {r['log_loss_bits']['independent']:>9.4f} "
            f"{r['brier']['exact']:>9.4f} {r['brier']['independent']:>9.4f}"
        )
    return lines
