r"""Traditional occupancy grid mapping: the evidence grid of Eq. (2.10), Section 2.4.

.. math:: l(m_k \mid z) = l(\lambda) + \sum_n \Delta(\kappa_{n,k}; z_n)

Each reading adds its update term ``Delta`` (a :class:`~ogm_ppl.models.delta.DeltaFamily`) to the cells
of its ray. ``Delta`` is the *increment* ``l(m_k | z_n) - l(m_k)`` of Eq. (2.10); with the thesis's
maximum-entropy prior ``lambda = 0.5`` the two coincide. The result is the amortised mean-field posterior
``q(m | z) = prod_k Bernoulli(sigmoid(l_k))`` (Section 2.5).

Two paths give the same numbers: a compiled kernel (default; optional OctoMap-style clamping after every
update) and a differentiable torch path (``index_add``) used when the family's parameters require
gradients, so that Delta can be fitted by gradient (Section 2.5).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba as nb
import numpy as np
import torch

from ogm_ppl._memory import check_fits
from ogm_ppl.grid import Grid
from ogm_ppl.inference._kernels.log_odds import (
    EvidenceRule,
    FixedRule,
    evidence_fixed_point,
    evidence_from_scans,
    evidence_update,
)
from ogm_ppl.models.delta import DeltaFamily
from ogm_ppl.raycast import Rays, ray_inputs
from ogm_ppl.scans import Scans

__all__ = [
    "LogOddsMap",
    "add_evidence",
    "evidence_grid",
    "evidence_grid_from_scans",
    "delta_table_for",
    "OCTOMAP_CLAMP",
]

#: OctoMap's default clamping thresholds in log-odds (probabilities 0.1192 and 0.971).
OCTOMAP_CLAMP = (-2.0, 3.5)


@dataclass(frozen=True, eq=False)
class LogOddsMap:
    """An occupancy grid in log-odds (an *evidence grid*) with an explicit unknown state.

    Attributes:
        grid: the grid.
        log_odds: ``K`` float64 tensor ``l_k``.
        observed: ``K`` bool tensor: cells that received a non-zero update. The others are *unknown*
            and hold the prior, kept apart from *free*.
    """

    grid: Grid
    log_odds: torch.Tensor
    observed: torch.Tensor

    @property
    def probabilities(self) -> torch.Tensor:
        """``p(m_k = 1 | z) = sigmoid(l_k)``, ``K``."""
        return torch.sigmoid(self.log_odds)

    def image(self, unknown: float | None = None) -> np.ndarray:
        """Probabilities reshaped to the grid; unknown cells set to ``unknown`` if given (e.g. NaN)."""
        p = self.probabilities.detach().cpu().numpy().copy()
        if unknown is not None:
            p[~self.observed.cpu().numpy()] = unknown
        return p.reshape(self.grid.shape)


def delta_table_for(rays: Rays, delta: DeltaFamily) -> tuple[torch.Tensor, int]:
    """The Delta table sized for ``rays`` and the index of its max-range column."""
    n_kappa = int(rays.lengths.max()) if rays.num_rays else 1
    hits = rays.z[~rays.is_max]
    n_z = int(max(hits.max() + 1 if hits.size else 0, n_kappa))
    return _checked(delta.table(n_kappa, n_z), delta), n_z


def _checked(table: torch.Tensor, delta) -> torch.Tensor:
    """The update-term table, refused when it holds NaN or infinity (a NaN parameter would silently
    threshold to an all-free map)."""
    bad = ~torch.isfinite(table.detach())
    if bad.any():
        k, z = (int(v) for v in bad.nonzero()[0])
        raise ValueError(
            f"{delta!r} gives a non-finite update term at kappa {k}, reading column {z}; "
            "check its parameters for NaN or infinity"
        )
    return table


def _logit(p: float) -> float:
    if not 0.0 < p < 1.0:
        raise ValueError(f"prior must lie in (0, 1), got {p!r}")
    return float(np.log(p) - np.log1p(-p))


def _check_clamp(clamp, l0: float):
    if clamp is None:
        return -np.inf, np.inf
    lo, hi = float(clamp[0]), float(clamp[1])
    if not lo < l0 < hi:
        raise ValueError(f"clamp {tuple(clamp)} must contain the prior log-odds {l0:.4f}")
    return lo, hi


def _check_range(delta: DeltaFamily, F_cells: float, where: str) -> None:
    """The shared fitted-setting check (range only), warning from the caller's caller."""
    import warnings

    from ogm_ppl.models.delta_setting import check_delta_setting

    if not (math.isfinite(F_cells) and F_cells > 0):
        return
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_delta_setting(delta, None, F_cells, where=where)
    for w in caught:
        warnings.warn(w.message, stacklevel=3)


def evidence_grid(
    rays: Rays,
    delta: DeltaFamily,
    prior: float = 0.5,
    clamp: tuple[float, float] | None = None,
    differentiable: bool = False,
    check_setting: bool = True,
) -> LogOddsMap:
    """Traditional OGM over all rays at once (Eq. 2.10).

    A fitted term (e.g. the shipped ``p21``) used at a maximum range far from the one it was fitted for
    warns (:class:`~ogm_ppl.inference.variational.FittedSettingWarning`, the check of
    :func:`~ogm_ppl.inference.variational.check_delta_setting` on the rays' median range in cells; the noise is
    not known here). ``check_setting=False`` skips it (callers that have checked with the noise).

    Args:
        rays: from :func:`~ogm_ppl.raycast.raycast`.
        delta: the update-term family.
        prior: cell prior ``lambda``; evidence starts at ``l(lambda)``.
        clamp: ``(lo, hi)`` log-odds bounds applied after every update, in reading order (OctoMap uses
            :data:`OCTOMAP_CLAMP`). Not differentiable.
        differentiable: ``True`` takes the torch path, whose result carries gradients with respect to
            the parameters of ``delta``; ``False`` (default) the compiled kernel.

    >>> from ogm_ppl import Grid, Scans, raycast
    >>> from ogm_ppl.models import Moravec
    >>> rays = raycast(Grid.line(6), Scans.one_d([3.0], max_range=5.0))
    >>> evidence_grid(rays, Moravec.haehnel()).log_odds.numpy().round(2).tolist()
    [-1.39, -1.39, -1.39, 1.39, 0.0, 0.0]
    """
    l0 = _logit(prior)
    K = rays.grid.num_cells
    _check_clamp(clamp, l0)  # refuses a clamp that is malformed or excludes the prior
    if check_setting and rays.num_rays:
        _check_range(delta, float(np.median(rays.max_range_cells())), "evidence_grid")
    if differentiable:
        if clamp is not None:
            raise ValueError("clamping is sequential and not differentiable; pass clamp=None")
        table, max_col = delta_table_for(rays, delta)
        zcol = torch.from_numpy(np.where(rays.is_max, max_col, rays.z))
        ray_of = torch.from_numpy(rays.ray_of_entry)
        vals = table[torch.from_numpy(rays.kappa), zcol[ray_of]]
        cells = torch.from_numpy(rays.cells)
        ev = torch.full((K,), l0, dtype=torch.float64).index_add(0, cells, vals)
        touched = torch.zeros(K, dtype=torch.bool)
        touched[cells[vals != 0]] = True
        return LogOddsMap(rays.grid, ev, touched)
    ev = np.full(K, l0, dtype=np.float64)
    touched = np.zeros(K, dtype=np.bool_)
    add_evidence(ev, touched, rays, delta, clamp)
    return LogOddsMap(rays.grid, torch.from_numpy(ev), torch.from_numpy(touched))


def add_evidence(
    evidence: np.ndarray,
    touched: np.ndarray,
    rays: Rays,
    delta: DeltaFamily,
    clamp: tuple[float, float] | None = None,
) -> None:
    """Eq. 2.10 in place: add every ray's update terms ``Delta(d)`` to ``evidence`` (``K`` float64 log-odds),
    ray by ray in reading order, and set ``touched`` (``K`` bool) where a term is non-zero; ``clamp`` clips
    after each update. Adding the rays of a log in batches gives the numbers of one call on all of them
    (the online maps keep traditional OGM so)."""
    lo, hi = (-np.inf, np.inf) if clamp is None else (float(clamp[0]), float(clamp[1]))
    if rays.num_rays == 0:
        return
    with torch.no_grad():
        table, max_col = delta_table_for(rays, delta)
    rule = EvidenceRule(np.ascontiguousarray(table.numpy()), max_col, lo, hi, clamp is not None)
    evidence_update(evidence, touched, rays.offsets, rays.cells, rays.z, rays.is_max, rule)


def evidence_grid_from_scans(
    grid: Grid,
    scans: Scans,
    delta: DeltaFamily,
    prior: float = 0.5,
    clamp: tuple[float, float] | None = None,
    check_setting: bool = True,
    threads: int | None = None,
) -> LogOddsMap:
    r"""Traditional OGM straight from scans: traversal and update fused in one compiled pass.

    Gives the numbers of ``evidence_grid(raycast(grid, scans), delta, ...)`` without building the
    ray -> cells structure: the fast path for large maps when only the evidence grid is wanted. The same
    setting check (``check_setting``) on ``scans.max_range / grid.resolution``.

    Without ``clamp`` the rays are walked by ``threads`` workers side by side, each taking chunks of rays while
    any is left (default ``numba.get_num_threads()``), and the terms are summed in fixed point: a term ``d`` is
    :math:`h 2^{-S} + l 2^{-S-S'}` with integers :math:`h = \mathrm{rint}(d 2^S)`,
    :math:`l = \mathrm{rint}((d 2^S - h) 2^{S'})`, :math:`S = \lfloor 61 - \log_2(R \max|\Delta| + 1) \rfloor`,
    :math:`S' = \lfloor 61 - \log_2 R \rfloor` (``R`` rays, each adding one term to a cell: no sum can overflow), so
    each term is off by at most :math:`2^{-S-S'-1}` (about ``1e-25`` for a log of 100,000 rays), the integer sums
    do not depend on their order, and the map is the same to the last bit for any ``threads``: the exact sum of
    the rounded terms, rounded twice (closer to the sum of the float64 terms than a sequential float sum). A
    walk stops past the last non-zero term of its column (under Hähnel's term, a hit ray's cells behind its
    reading). With ``clamp`` (clipped after every update, so order matters) one thread
    adds the terms in reading order.
    """
    l0 = _logit(prior)
    lo, hi = _check_clamp(clamp, l0)
    if check_setting:
        _check_range(delta, float(scans.max_range) / float(grid.resolution), "evidence_grid_from_scans")
    if threads is not None and (not isinstance(threads, int) or isinstance(threads, bool) or threads < 1):
        raise ValueError(f"threads must be a positive integer, got {threads!r}")
    parts = 1 if clamp is not None else (int(threads) if threads is not None else nb.get_num_threads())
    ri = ray_inputs(grid, scans)
    cap = ri.capacity()
    check_fits(
        delta.table_bytes(cap, cap) + 8 * cap * (cap + 1) + (9 * parts + 8) * grid.num_cells,
        f"traditional OGM on a {' x '.join(map(str, grid.shape))} grid (building the update term's table "
        f"({type(delta).__name__}) "
        f"of {cap:,} x {cap + 1:,} float64 entries, a ray's most cells up to the sensor's maximum range of "
        f"{float(scans.max_range):g} m, and a copy of it; {9 * parts + 8} bytes a cell with {parts} thread(s))",
        "use a coarser resolution or a shorter usable range",
    )
    with torch.no_grad():
        table = np.ascontiguousarray(_checked(delta.table(cap, cap), delta).detach().numpy())
    big = float(np.abs(table).max()) if table.size else 0.0
    R = len(ri.length)
    bits, lo_bits = math.floor(61 - math.log2(R * big + 1)), math.floor(61 - math.log2(R + 1))
    if clamp is None and bits >= 8:
        rule = fixed_rule(table, cap, bits, lo_bits)
        acc = np.zeros((parts, grid.num_cells, 2), np.int64)
        seen = np.zeros((parts, grid.num_cells), np.bool_)
        prev = nb.get_num_threads()
        nb.set_num_threads(max(1, min(parts, int(nb.config.NUMBA_NUM_THREADS))))  # type: ignore[attr-defined]
        try:
            evidence_fixed_point(ri.arrays(), grid.rows, grid.cols, acc, seen, rule)
        finally:
            nb.set_num_threads(prev)
        total = acc.sum(0) if parts > 1 else acc[0]
        ev = l0 + (
            np.ldexp(total[:, 0].astype(np.float64), -bits) + np.ldexp(total[:, 1].astype(np.float64), -bits - lo_bits)
        )
        return LogOddsMap(grid, torch.from_numpy(ev), torch.from_numpy(seen.any(0)))
    ev = np.full(grid.num_cells, l0, dtype=np.float64)
    touched = np.zeros(grid.num_cells, dtype=np.bool_)
    evidence_from_scans(
        ri.arrays(), grid.rows, grid.cols, ev, touched, EvidenceRule(table, cap, lo, hi, clamp is not None)
    )
    return LogOddsMap(grid, torch.from_numpy(ev), torch.from_numpy(touched))


def fixed_rule(table: np.ndarray, max_col: int, bits: int, lo_bits: int) -> FixedRule:
    """The :class:`~ogm_ppl.inference._kernels.log_odds.FixedRule` of a float64 term table (``rows x cols``): each
    term as integers ``(h, l)`` with ``term ~ h 2^-bits + l 2^-(bits + lo_bits)`` (:func:`evidence_grid_from_scans`),
    the non-zero mask and each column's rows up to its last non-zero term."""
    nonzero = table != 0.0
    rows = np.arange(1, table.shape[0] + 1)[:, None]
    stop = (nonzero * rows).max(0).astype(np.int64) if table.size else np.zeros(table.shape[1], np.int64)
    scaled = np.ldexp(table, bits)
    hi = np.rint(scaled)
    lo = np.rint(np.ldexp(scaled - hi, lo_bits))  # scaled - hi is exact: |scaled| < 2^61
    fixed = np.ascontiguousarray(np.stack([hi.T, lo.T], -1).astype(np.int64))  # cols x rows x 2
    return FixedRule(fixed, np.ascontiguousarray(nonzero.T), stop, int(max_col))
