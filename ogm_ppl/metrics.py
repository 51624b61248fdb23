r"""Comparing occupancy grids: KL divergence, cross-entropy (Section 2.5), precision / recall / F1
against a binary map, masks (Fig. 6.16b), and ROC AUC.

For two grids of cell probabilities ``p`` (the benchmark) and ``q`` (the estimate), per cell

.. math::
    D_{KL}(p_k \| q_k) = \sum_{m_k \in \{0,1\}} p(m_k) \log \frac{p(m_k)}{q(m_k)}, \qquad
    H(p_k, q_k) = -\sum_{m_k} p(m_k) \log q(m_k),

and the map-level values are sums over cells. All functions accept numpy arrays or torch tensors; the
KL and cross-entropy functions return torch tensors (differentiable in ``q``), the detection metrics
numpy values.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

__all__ = [
    "kl_per_cell",
    "kl_divergence",
    "cross_entropy_per_cell",
    "cross_entropy",
    "PRCurve",
    "precision_recall",
    "best_f1",
    "roc_auc",
    "near_mapped_mask",
    "nll_bits",
    "saturated_cells",
    "brier_score",
    "expected_calibration_error",
    "Reliability",
    "reliability",
    "occupied_iou",
    "prediction_scores",
]


def _prob(x, name: str) -> torch.Tensor:
    t = x if isinstance(x, torch.Tensor) else torch.as_tensor(np.asarray(x, dtype=float))
    t = t.to(torch.float64)
    if torch.isnan(t).any():
        raise ValueError(f"{name} contains NaN at index {int(torch.isnan(t).nonzero()[0, 0])}")
    bad = (t < 0) | (t > 1)
    if bad.any():
        i = int(bad.flatten().nonzero()[0, 0])
        raise ValueError(f"{name} must hold probabilities in [0, 1]; index {i} is {float(t.flatten()[i])}")
    return t


def _xlogy(x: torch.Tensor, y: torch.Tensor) -> torch.Tensor:
    return torch.special.xlogy(x, y)


def cross_entropy_per_cell(p, q) -> torch.Tensor:
    """``H(p_k, q_k)`` in nats, elementwise (``0 log 0 = 0``; infinite where q rules out p's mass)."""
    p, q = _prob(p, "p"), _prob(q, "q")
    return -(_xlogy(p, q) + _xlogy(1 - p, 1 - q))


def kl_per_cell(p, q) -> torch.Tensor:
    """``D_KL(p_k || q_k)`` in nats, elementwise."""
    p, q = _prob(p, "p"), _prob(q, "q")
    return _xlogy(p, p) + _xlogy(1 - p, 1 - p) - _xlogy(p, q) - _xlogy(1 - p, 1 - q)


def _masked_sum(x: torch.Tensor, mask) -> torch.Tensor:
    if mask is None:
        return x.sum()
    m = torch.as_tensor(np.asarray(mask, dtype=bool)).reshape(x.shape)
    return x[m].sum()


def cross_entropy(p, q, mask=None) -> torch.Tensor:
    """Summed cross-entropy ``H(p, q) = sum_k H(p_k, q_k)`` over the (optionally masked) cells."""
    return _masked_sum(cross_entropy_per_cell(p, q), mask)


def kl_divergence(p, q, mask=None) -> torch.Tensor:
    """Summed ``D_KL(p || q) = sum_k D_KL(p_k || q_k)`` over the (optionally masked) cells."""
    return _masked_sum(kl_per_cell(p, q), mask)


@dataclass(frozen=True)
class PRCurve:
    """Precision, recall and F1 at each threshold (a cell is called occupied when ``p > threshold``)."""

    thresholds: np.ndarray
    precision: np.ndarray
    recall: np.ndarray
    f1: np.ndarray
    tp: np.ndarray
    fp: np.ndarray
    fn: np.ndarray


def _flat(estimate, truth, mask):
    est = np.asarray(
        estimate.detach().cpu().numpy() if isinstance(estimate, torch.Tensor) else estimate,
        dtype=float,
    ).ravel()
    tru = np.asarray(truth, dtype=bool).ravel()
    if est.shape != tru.shape:
        raise ValueError(f"estimate has {est.size} cells but truth has {tru.size}")
    if mask is not None:
        m = np.asarray(mask, dtype=bool).ravel()
        if m.shape != tru.shape:
            raise ValueError(f"mask has {m.size} cells but truth has {tru.size}")
        est, tru = est[m], tru[m]
    if np.isnan(est).any():
        raise ValueError(f"estimate contains NaN at (masked) index {int(np.flatnonzero(np.isnan(est))[0])}")
    return est, tru


def precision_recall(estimate, truth, thresholds=None, mask=None) -> PRCurve:
    """Precision, recall and F1 of ``estimate > t`` against the binary ``truth`` for every ``t``.

    Args:
        estimate: cell probabilities; truth: binary map of the same size.
        thresholds: default 0.01..0.99 in steps of 0.01.
        mask: boolean, cells to score (e.g. :func:`near_mapped_mask`).

    Precision is 1 where nothing is called occupied (no false positives); F1 is 0 where precision
    and recall are both 0.
    """
    est, tru = _flat(estimate, truth, mask)
    thr = np.linspace(0.01, 0.99, 99) if thresholds is None else np.atleast_1d(np.asarray(thresholds, float))
    called = est[None, :] > thr[:, None]
    tp = (called & tru).sum(1)
    fp = (called & ~tru).sum(1)
    fn = (~called & tru).sum(1)
    with np.errstate(invalid="ignore", divide="ignore"):
        prec = np.where(tp + fp > 0, tp / np.maximum(tp + fp, 1), 1.0)
        rec = np.where(tp + fn > 0, tp / np.maximum(tp + fn, 1), 0.0)
        f1 = np.where(prec + rec > 0, 2 * prec * rec / (prec + rec), 0.0)
    return PRCurve(thr, prec, rec, f1, tp, fp, fn)


def best_f1(estimate, truth, thresholds=None, mask=None) -> tuple[float, float]:
    """``(best F1, its threshold)`` over ``thresholds`` (the first best on ties)."""
    c = precision_recall(estimate, truth, thresholds, mask)
    i = int(np.argmax(c.f1))
    return float(c.f1[i]), float(c.thresholds[i])


def roc_auc(estimate, truth, mask=None) -> float:
    """Area under the ROC curve: the probability that a random occupied cell scores higher than a
    random free one (ties count one half); the Mann-Whitney statistic, exact."""
    from scipy.stats import rankdata

    est, tru = _flat(estimate, truth, mask)
    n1, n0 = int(tru.sum()), int((~tru).sum())
    if n1 == 0 or n0 == 0:
        raise ValueError("roc_auc needs both occupied and free cells in truth (after masking)")
    ranks = rankdata(est)
    return float((ranks[tru].sum() - n1 * (n1 + 1) / 2) / (n1 * n0))


def near_mapped_mask(mapped, distance: float = 10.0) -> np.ndarray:
    """Cells within ``distance`` cells (Euclidean, centre to centre) of a mapped cell (Fig. 6.16b).

    ``mapped`` is a boolean map of the grid's shape (e.g. ``LogOddsMap.observed`` reshaped).
    """
    from scipy.ndimage import distance_transform_edt

    mapped = np.asarray(mapped, dtype=bool)
    if not mapped.any():
        return np.zeros_like(mapped)
    return distance_transform_edt(~mapped) <= distance


# ----------------------------------------------------------------------------------- prediction scores
# Scores of a map as a *predictor* of the true map (Chapter 5's question: does a prior fill in what was
# not seen?). Each takes cell probabilities ``q``, the binary truth and an optional mask.


def nll_bits(estimate, truth, mask=None, eps: float = 1e-6) -> float:
    r"""Mean negative log-likelihood of the true map under the cell probabilities, in bits per cell:
    :math:`-\frac{1}{|M|}\sum_{k \in M} \log_2 q_k^{m_k} (1 - q_k)^{1 - m_k}` (``q`` clipped to
    ``[eps, 1 - eps]`` so that one confident mistake costs ``log2(1/eps)`` bits, not infinity)."""
    est, tru = _flat(estimate, truth, mask)
    if est.size == 0:
        return float("nan")
    q = np.clip(est, eps, 1 - eps)
    return float(-np.mean(np.where(tru, np.log2(q), np.log2(1 - q))))


def saturated_cells(estimate, mask=None, eps: float = 1e-6) -> int:
    """How many cells (of ``mask``) have a probability within ``eps`` of 0 or 1: *saturated* marginals, the
    ones whose mistakes cost the full ``log2(1/eps)`` bits of :func:`nll_bits`. A map whose scored cells are
    mostly saturated is near-binary: its threshold curves (best F1, AUC) say little about calibration."""
    q = np.asarray(estimate, dtype=np.float64).ravel()
    if mask is not None:
        q = q[np.asarray(mask, dtype=bool).ravel()]
    return int(((q <= eps) | (q >= 1 - eps)).sum())


def brier_score(estimate, truth, mask=None) -> float:
    """Mean squared difference between the cell probabilities and the binary truth."""
    est, tru = _flat(estimate, truth, mask)
    return float(np.mean((est - tru) ** 2)) if est.size else float("nan")


@dataclass(frozen=True)
class Reliability:
    r"""A reliability diagram's numbers: ``bins`` equal-width probability bins ``B_b = [b/B, (b+1)/B)`` (the
    last one closed), and per bin the number of cells ``n_b``, the sum of their probabilities
    ``S_b = sum_{k in B_b} q_k`` and the number of them occupied ``O_b = sum_{k in B_b} m_k``.

    Sums, not means, so that diagrams of several maps pool by adding (:meth:`pooled`); the means
    ``mean_q = S_b / n_b`` and ``occupied = O_b / n_b`` are NaN for an empty bin.
    """

    edges: np.ndarray  # B + 1 float64
    count: np.ndarray  # B int64: n_b
    sum_q: np.ndarray  # B float64: S_b
    sum_occupied: np.ndarray  # B float64: O_b

    @property
    def mean_q(self) -> np.ndarray:
        """``S_b / n_b``: the mean predicted probability of bin ``b`` (NaN if empty)."""
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(self.count > 0, self.sum_q / np.maximum(self.count, 1), np.nan)

    @property
    def occupied(self) -> np.ndarray:
        """``O_b / n_b``: the share of bin ``b``'s cells that are occupied (NaN if empty)."""
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(self.count > 0, self.sum_occupied / np.maximum(self.count, 1), np.nan)

    @property
    def ece(self) -> float:
        r""":math:`\mathrm{ECE} = \sum_b \frac{n_b}{n} |\bar q_b - \bar m_b| = \frac{1}{n} \sum_b |S_b - O_b|`
        (NaN for no cells)."""
        n = int(self.count.sum())
        return float(np.abs(self.sum_q - self.sum_occupied).sum() / n) if n else float("nan")

    def to_dict(self) -> dict[str, list]:
        """JSON-ready lists (``edges``, ``count``, ``sum_q``, ``sum_occupied``)."""
        return {
            "edges": self.edges.tolist(),
            "count": self.count.tolist(),
            "sum_q": self.sum_q.tolist(),
            "sum_occupied": self.sum_occupied.tolist(),
        }

    @classmethod
    def from_dict(cls, d: dict) -> Reliability:
        """The inverse of :meth:`to_dict`, checked: ``B + 1`` increasing edges and ``B`` of each sum."""
        try:
            edges = np.asarray(d["edges"], dtype=np.float64)
            count = np.asarray(d["count"], dtype=np.int64)
            sum_q = np.asarray(d["sum_q"], dtype=np.float64)
            sum_occ = np.asarray(d["sum_occupied"], dtype=np.float64)
        except (KeyError, TypeError, ValueError) as e:
            raise ValueError(f"not a reliability record ({type(e).__name__}: {e})") from None
        B = len(count)
        if edges.shape != (B + 1,) or sum_q.shape != (B,) or sum_occ.shape != (B,) or not (np.diff(edges) > 0).all():
            raise ValueError(
                f"a reliability record needs B + 1 increasing edges and B counts and sums; got {len(edges)} edges, "
                f"{B} counts, {len(sum_q)} and {len(sum_occ)} sums"
            )
        return cls(edges, count, sum_q, sum_occ)

    @staticmethod
    def pooled(parts) -> Reliability:
        """The diagram of the union of the cells of ``parts`` (same bins): counts and sums added."""
        parts = list(parts)
        if not parts:
            raise ValueError("pooled needs at least one reliability diagram")
        e = parts[0].edges
        if any(p.edges.shape != e.shape or not np.allclose(p.edges, e) for p in parts):
            raise ValueError("pooled needs diagrams with the same bins")
        return Reliability(
            e.copy(),
            np.sum([p.count for p in parts], axis=0),
            np.sum([p.sum_q for p in parts], axis=0),
            np.sum([p.sum_occupied for p in parts], axis=0),
        )


def reliability(estimate, truth, mask=None, bins: int = 10) -> Reliability:
    r"""The reliability diagram of cell probabilities ``q`` against the binary truth ``m``.

    Cell ``k`` falls in bin ``b = min(floor(B q_k), B - 1)`` of ``B = bins`` equal-width bins; returned are
    ``n_b``, ``S_b = sum q_k`` and ``O_b = sum m_k`` per bin (:class:`Reliability`). A calibrated map has
    ``O_b / n_b ~ S_b / n_b`` in every bin.
    """
    if int(bins) < 1:
        raise ValueError(f"bins must be >= 1, got {bins}")
    bins = int(bins)
    est, tru = _flat(estimate, truth, mask)
    if ((est < 0) | (est > 1)).any():
        i = int(np.flatnonzero((est < 0) | (est > 1))[0])
        raise ValueError(f"estimate must hold probabilities in [0, 1]; (masked) index {i} is {est[i]}")
    b = np.minimum((est * bins).astype(np.int64), bins - 1)
    return Reliability(
        np.linspace(0.0, 1.0, bins + 1),
        np.bincount(b, minlength=bins).astype(np.int64),
        np.bincount(b, weights=est, minlength=bins).astype(np.float64),
        np.bincount(b, weights=tru.astype(np.float64), minlength=bins),
    )


def expected_calibration_error(estimate, truth, mask=None, bins: int = 10) -> float:
    r"""Expected calibration error over ``bins`` equal-width probability bins:
    :math:`\sum_b \frac{n_b}{n} |\bar q_b - \bar m_b|` (mean probability vs occupied share per bin;
    :attr:`Reliability.ece` of :func:`reliability`)."""
    return reliability(estimate, truth, mask, bins).ece


def occupied_iou(estimate, truth, mask=None, threshold: float = 0.5, unknown=None) -> float:
    """Intersection over union of the occupied class at ``threshold``, with cells in ``unknown`` counted
    free (the convention of learned map-prediction work, for comparability)."""
    est = np.asarray(estimate.detach().cpu().numpy() if isinstance(estimate, torch.Tensor) else estimate, float)
    est = est.ravel().copy()
    if unknown is not None:
        est[np.asarray(unknown, bool).ravel()] = 0.0
    est, tru = _flat(est, truth, mask)
    called = est > threshold
    union = int((called | tru).sum())
    return float((called & tru).sum() / union) if union else float("nan")


def prediction_scores(estimate, truth, mask=None, unknown=None) -> dict[str, float]:
    """All prediction scores of one map on one mask: NLL (bits/cell), ECE, Brier, best F1 (of the occupied
    class: NaN where the mask holds no occupied cell, as recall is then undefined), ROC AUC (NaN where the mask
    holds only one class) and occupied IoU at 0.5 with ``unknown`` counted free. Means over maps skip the NaNs."""
    est, tru = _flat(estimate, truth, mask)
    out = {
        "cells": int(est.size),
        "nll_bits": nll_bits(estimate, truth, mask),
        "ece": expected_calibration_error(estimate, truth, mask),
        "brier": brier_score(estimate, truth, mask),
        "best_f1": best_f1(estimate, truth, mask=mask)[0] if tru.any() else float("nan"),
        "iou": occupied_iou(estimate, truth, mask, unknown=unknown),
    }
    out["auc"] = roc_auc(estimate, truth, mask) if 0 < tru.sum() < tru.size else float("nan")
    return out
