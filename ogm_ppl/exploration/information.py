r"""Information gain of a candidate sensor pose from posterior samples of the map.

For a candidate pose ``x`` with beams ``b = 1..B``, the quantity an explorer ranks poses by is the mutual
information between the map and the readings the candidate would take, given the readings so far:

.. math::
    I(m; z_{new} \mid z) = H(z_{new} \mid z) - H(z_{new} \mid m, z),

with ``m ~ p(m | z)`` represented by ``S`` posterior samples (an MCMC chain, :mod:`ogm_ppl.inference.mcmc`)
and ``z_new ~ p(z_new | m)`` the forward sensor model (Section 2.6). All values are in **bits**.

**Per beam** (:func:`beam_information`). A reading depends on the map only through its first hit ``f_b``
(static world, Section 2.6), so ``I(m; z_b | z) = I(f_b; z_b | z)``: a finite sum over the first-hit
distribution of the beam across the samples (``p(f_b = kappa)``: the weight of the samples whose first
occupied cell on the beam is ``kappa``; last outcome: none on the ray) and over the sensor's readings.
The result is **exact for the empirical posterior** of the samples (for the weighted maps given): two
documented cut-offs keep it fast and change it by less than ``1e-13`` bits: first hits of probability
``<= 1e-15`` are left out, and a normal bin farther than 8.5 standard deviations from the first hit (mass
``< 1e-17``) gets no Gaussian mass.

**Which sensors.** Any :class:`~ogm_ppl.sensors.SensorModel` whose ``compiled(bin_width)`` returns a reading
bundle of a registered kind (:mod:`ogm_ppl.sensors_compiled`): the kernels below run the kind's compiled reading
model (one specialisation per kind). The shipped :class:`~ogm_ppl.sensors.GaussianRange` and
:class:`~ogm_ppl.sensors.PatternMatch` have one; a sensor of one's own registers its kind the same way, and a
sensor without one is refused (``TypeError`` naming what to implement).

**How readings are discretised.** A discrete sensor (``continuous_range = False``,
:class:`~ogm_ppl.sensors.PatternMatch`) reads a kappa ``0..F`` or max range: the sum runs over those
``F + 2`` outcomes. A continuous sensor (:class:`~ogm_ppl.sensors.GaussianRange`) reads a range; its range
is quantised into bins of ``bin_width`` cells in the continuous kappa coordinate ``z = r + 1/2``
(:mod:`ogm_ppl.sensors`), edges at ``-1/2 + j w``, ``j = 1..J-1``, the first bin open to ``-inf``, the last
ending at ``F + 1/2`` (the max-range censoring point), plus the max-range atom: ``J + 1 = ceil((F + 1) / w) + 1``
outcomes. The bin probabilities are exact (for the Gaussian: differences of the normal CDF, the uniform
``p_rand`` part by length, the max-range atom by the censored tail), so the sum is the exact MI of the
*quantised* reading. By the data-processing inequality it is a lower bound on the MI of the continuous reading,
and it increases to it as ``bin_width -> 0`` (halving the width nests the partitions; the tests check both).

**Whole scan** (:func:`scan_information`). The beams of one scan are dependent through the map, so their
information is not the sum of the per-beam values. With ``F_s`` the first hits of all beams in sample ``s``
and ``p_S(Z) = sum_s w_s p(Z | F_s)`` (beams independent given the map):

.. math::
    I(m; Z) = E_{s \sim w} E_{Z \sim p(\cdot | F_s)} [\log p(Z | F_s) - \log p_S(Z)],

estimated by ``N = num_draws`` draws ``(s_n, Z_n)``; the inner mean over the samples is computed exactly,
so for the empirical posterior the estimator is unbiased and its standard error is the sample standard
deviation over ``sqrt(N)``. (As an estimate of the MI under the true posterior it is the nested Monte-Carlo
estimator, consistent as ``S`` grows.) Continuous readings are scored by their density unless
``bin_width`` is given. Under the empirical posterior ``I(m; Z) <= H(samples) <= log2 S`` bits: a scan that
tells the ``S`` samples apart saturates there, so candidates compare only below that ceiling (more samples
raise it); the per-beam values have no such ceiling per beam but add up information the beams share.

**Baseline** (:func:`independent_information`): the independent-cell information gain that FSMI (Zhang et
al., ICRA 2019) and FCMI (Henderson et al., ICRA 2020) compute: per beam, ``I(f_b; z_b)`` under the product
distribution of the cell marginals (traditional OGM's or the samples'), whose first-hit distribution is
Eq. (4.7) (:func:`~ogm_ppl.posterior.first_hit_independent`), with the same reading model as above.

**Expected newly observed cells** (:func:`expected_new_cells`): not an information gain but the quantity a
coverage explorer wants (MapEx, ICRA 2025, ray-casts each candidate in predicted maps): the expected number of
cells not yet observed (``observed`` False) that the candidate's beams would cross before their first hit,

.. math::
    E[N_c \mid z] = \sum_s w_s \,\Big|\bigcup_b V_b(m^{(s)}) \setminus O\Big| \Big/ \sum_s w_s,

with :math:`V_b(m)` the cells of beam ``b`` from the sensor's cell up to (not including; ``include_hit``:
including) its first occupied cell in map ``m``, :math:`O` the observed cells, and the sums over the samples
with the candidate's cell free. A cell several beams cross counts once per sample. Exact for the weighted
maps; it ignores range noise (a reading near max range observes up to the hit either way).

**The candidate's own cell** is known to be free (the robot stands there; :class:`~ogm_ppl.OccupancyModel`
pins sensor cells the same way): the samples are conditioned on it (those with it occupied are dropped
for that candidate), and a marginal of 1 there is an error. Rays are cut at the grid edge; cells beyond
it are taken as free (a beam leaving the grid with no hit in it gives the no-hit reading distribution).

**Where the work is done.** :mod:`~ogm_ppl.exploration.rays` casts the candidates' beams,
:mod:`~ogm_ppl.exploration.first_hits` packs the samples into bit sets and walks the rays through them,
:mod:`~ogm_ppl.exploration.beam_mi` and :mod:`~ogm_ppl.exploration.scan_mi` hold the compiled estimators; this
module holds the functions to call.

>>> import numpy as np
>>> from ogm_ppl import GaussianRange, Grid
>>> g = Grid((1, 6))
>>> cr = candidate_rays(g, [[0.5, 0.5, 0.0]], [0.0], max_range=5.0)
>>> wall_at = lambda k: np.eye(6, dtype=np.uint8)[k]
>>> samples = np.stack([wall_at(1), wall_at(4)])  # half the samples: wall at 1, half: wall at 4
>>> round(float(beam_information(g, GaussianRange(0.3), samples, cr)[0, 0]), 4)  # one bit
1.0
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
import torch

from ogm_ppl.exploration.beam_mi import beam_mi_kernel
from ogm_ppl.exploration.first_hits import first_hits_kernel, new_cells_kernel, packed_samples
from ogm_ppl.exploration.rays import CandidateRays, candidate_rays, check_rays, ray_table, refuse_blocked
from ogm_ppl.exploration.scan_mi import Draws, scan_mi_kernel
from ogm_ppl.grid import Grid
from ogm_ppl.sensors import SensorModel
from ogm_ppl.sensors_compiled import bin_prob, is_continuous, kind_of, num_outcomes

__all__ = [
    "CandidateRays",
    "ScanInformation",
    "beam_information",
    "candidate_rays",
    "expected_new_cells",
    "first_hit_distribution",
    "independent_first_hits",
    "independent_information",
    "reading_distribution",
    "scan_information",
]

_LN2 = math.log(2.0)


def _compiled_reading(sensor: SensorModel, bin_width: float | None) -> NamedTuple:
    """The sensor's reading bundle (:meth:`~ogm_ppl.sensors.SensorModel.compiled`), of a registered kind."""
    face = getattr(sensor, "compiled", None)
    reading = face(bin_width) if callable(face) else None
    if reading is None:
        raise TypeError(
            f"no compiled reading model for {type(sensor).__name__}: the information gain needs the sensor's "
            "compiled face, a SensorModel.compiled(bin_width) that returns a reading bundle of a kind registered "
            "with ogm_ppl.sensors_compiled.register (see ogm_ppl.sensors_compiled)"
        )
    kind_of(reading)  # a TypeError naming the bundle class if its kind is not registered
    return reading


def _ray_F(rays: CandidateRays, reading) -> np.ndarray:
    """``F`` of every ray: the max range in cells (continuous) or the sensor's last kappa (discrete)."""
    if is_continuous(reading):
        return np.full(rays.offsets.shape[0] - 1, rays.max_range_cells)
    return (np.maximum(rays.range_len, rays.lengths) - 1).astype(np.float64)


def reading_distribution(sensor: SensorModel, f, F: float, bin_width: float | None = None) -> torch.Tensor:
    """The reading outcome probabilities the information gain sums over (module docstring), for first hits
    ``f`` (``N``: continuous kappa ``t + 1/2`` for a continuous sensor, integer kappa for a discrete one;
    ``nan`` for no occupied cell on the ray) on a ray with ``F``: ``N x (J + 1)`` float64, column ``J`` the
    max-range outcome. Rows sum to one."""
    reading = _compiled_reading(sensor, bin_width)
    f = np.atleast_1d(np.asarray(f, dtype=np.float64))
    J = int(num_outcomes(reading, float(F)))
    out = np.empty((f.shape[0], J + 1))
    for i, fi in enumerate(f):
        for j in range(J + 1):
            out[i, j] = bin_prob(reading, j, J, 0.0 if np.isnan(fi) else fi, bool(np.isnan(fi)), float(F))
    return torch.from_numpy(out)


def first_hit_distribution(grid: Grid, samples, candidate_rays: CandidateRays, weights=None) -> torch.Tensor:
    """``p(f_r = kappa)`` of every candidate ray across the samples (weights ``w_s``, default ``1/S``),
    conditioned on the candidate's cell being free: ``C*B x (Lmax + 1)`` float64, column ``len_r`` for no
    occupied cell on the ray, zeros beyond (the column convention of ``OccupancyModel.loglik_table``).

    Raises:
        ValueError: bad samples or weights, or a candidate whose cell is occupied in every sample.
    """
    check_rays(grid, candidate_rays)
    pf, _ = _first_hits(grid, samples, candidate_rays, weights)
    return torch.from_numpy(pf)


def _first_hits(grid: Grid, samples, rays: CandidateRays, weights) -> tuple[np.ndarray, np.ndarray]:
    ps = packed_samples(samples, grid.num_cells, weights)
    pf, totals = first_hits_kernel(ps, ray_table(rays), int(rays.lengths.max()))
    refuse_blocked(rays, totals <= 0, "every sample")
    return pf, totals


def _mi_bits(pf: np.ndarray, reading, rays: CandidateRays) -> torch.Tensor:
    mi = beam_mi_kernel(pf, ray_table(rays), _ray_F(rays, reading), reading)
    return torch.from_numpy(mi / _LN2).reshape(rays.num_candidates, rays.num_beams)


def beam_information(
    grid: Grid,
    sensor: SensorModel,
    samples,
    candidate_rays: CandidateRays,
    *,
    weights=None,
    bin_width: float | None = None,
) -> torch.Tensor:
    r"""Per-beam ``I(m; z_b | z) = I(f_b; z_b)`` in bits under the empirical posterior of ``samples``.

    Args:
        grid: the grid (``K = H*W`` cells).
        sensor: a sensor with a compiled reading model (:meth:`~ogm_ppl.sensors.SensorModel.compiled`:
            :class:`~ogm_ppl.sensors.GaussianRange`, :class:`~ogm_ppl.sensors.PatternMatch`, or one's own).
        samples: ``S x K`` 0/1 maps (uint8 / bool), e.g. posterior samples of a chain.
        candidate_rays: from :func:`candidate_rays` on ``grid``.
        weights: optional ``S`` non-negative weights of the maps (default: equal); with the ``2^L`` maps of
            an enumerable problem and their exact posterior probabilities the result is the exact MI.
        bin_width: width in cells of the range bins of a continuous sensor (default 1 cell; module docstring).

    Returns:
        ``C x B`` float64: exact (to rounding) for the weighted maps; each sample set is conditioned on the
        candidate's cell being free.
    """
    check_rays(grid, candidate_rays)
    reading = _compiled_reading(sensor, bin_width)
    pf, _ = _first_hits(grid, samples, candidate_rays, weights)
    return _mi_bits(pf, reading, candidate_rays)


def expected_new_cells(
    grid: Grid, samples, candidate_rays: CandidateRays, observed, *, weights=None, include_hit: bool = False
) -> torch.Tensor:
    r"""Expected number of not-yet-observed cells each candidate's scan would observe, over the samples
    (module docstring): ``E[N_c | z] = sum_s w_s |union_b V_b(m_s) \ O| / sum_s w_s``.

    Args:
        grid: the grid (``K`` cells).
        samples: ``S x K`` 0/1 maps (posterior samples of a chain, or draws from independent marginals).
        candidate_rays: from :func:`candidate_rays` on ``grid`` (the candidate's own cell is ``kappa = 0``).
        observed: ``K`` bool (or grid-shaped): cells already observed; only the others are counted.
        weights: optional ``S`` non-negative weights of the maps (default equal).
        include_hit: count the first occupied cell of each beam too (default: the free cells before it,
            what a coverage of the free space counts).

    Returns:
        ``C`` float64 cells, each sample set conditioned on the candidate's cell being free.

    Raises:
        ValueError: bad samples, weights or ``observed``, or a candidate whose cell is occupied in every sample.
    """
    check_rays(grid, candidate_rays)
    obs = np.asarray(observed.cpu() if isinstance(observed, torch.Tensor) else observed)
    if obs.size != grid.num_cells:
        raise ValueError(f"observed must be a mask of the grid's {grid.num_cells} cells, got {obs.size} values")
    if obs.dtype != np.bool_ and not np.isin(obs, (0, 1)).all():
        raise ValueError("observed must hold only 0/1 (or bool) values")
    unobserved = np.ascontiguousarray(obs.reshape(-1) == 0)
    ps = packed_samples(samples, grid.num_cells, weights)
    rays = candidate_rays
    out, totals = new_cells_kernel(ps, ray_table(rays), unobserved, bool(include_hit))
    refuse_blocked(rays, totals <= 0, "every sample")
    return torch.from_numpy(out)


def independent_first_hits(grid: Grid, marginals, candidate_rays: CandidateRays) -> torch.Tensor:
    r"""``p(f_r = kappa) = p_kappa prod_{0 < i < kappa} (1 - p_i)`` (Eq. 4.7,
    :func:`~ogm_ppl.posterior.first_hit_independent`) of every candidate ray, with the candidate's own cell
    free: ``C*B x (Lmax + 1)`` float64 in the layout of :func:`first_hit_distribution`.

    Raises:
        ValueError: marginals not ``K`` probabilities, or a candidate whose cell has marginal 1.
    """
    check_rays(grid, candidate_rays)
    p = torch.as_tensor(marginals, dtype=torch.float64).detach().cpu().reshape(-1)
    K = grid.num_cells
    if p.shape != (K,):
        raise ValueError(f"marginals must hold one probability per cell ({K}), got {p.numel()}")
    if not torch.isfinite(p).all() or (p < 0).any() or (p > 1).any():
        raise ValueError("marginals must be probabilities in [0, 1]")
    rays = candidate_rays
    refuse_blocked(rays, (p[torch.from_numpy(rays.pose_cells)] >= 1).numpy(), "the marginals (probability 1)")
    lengths = torch.from_numpy(rays.lengths)
    R, Wmax = len(lengths), int(lengths.max())
    dense = torch.full((R, Wmax), K, dtype=torch.int64)
    entry_ray = torch.repeat_interleave(torch.arange(R), lengths)
    kappa = torch.arange(len(rays.cells)) - torch.repeat_interleave(torch.from_numpy(rays.offsets[:-1]), lengths)
    dense[entry_ray, kappa] = torch.from_numpy(rays.cells)
    pp = torch.cat([p, p.new_zeros(1)])[dense]  # padding: free
    pp[:, 0] = 0.0  # the candidate's own cell is free
    free_before = torch.cumprod(torch.cat([pp.new_ones(R, 1), 1 - pp], 1), 1)  # R x (Wmax + 1)
    pf = torch.zeros(R, Wmax + 1, dtype=torch.float64)
    pf[:, :Wmax] = pp * free_before[:, :-1]
    pf[torch.arange(R), lengths] = free_before[torch.arange(R), lengths]
    return pf


def independent_information(
    grid: Grid, sensor: SensorModel, marginals, candidate_rays: CandidateRays, *, bin_width: float | None = None
) -> torch.Tensor:
    r"""The FSMI / FCMI-style independent-cell information gain per beam, in bits: ``I(f_b; z_b)`` with
    ``f_b`` distributed as under independent cells with the given marginals (:func:`independent_first_hits`),
    the same reading model as :func:`beam_information`.

    Args:
        marginals: ``K`` occupancy probabilities (traditional OGM's, or the samples' mean).

    Returns:
        ``C x B`` float64 (exact for the product distribution, to rounding).
    """
    reading = _compiled_reading(sensor, bin_width)
    pf = independent_first_hits(grid, marginals, candidate_rays).numpy()
    return _mi_bits(np.ascontiguousarray(pf), reading, candidate_rays)


@dataclass(frozen=True)
class ScanInformation:
    """Nested Monte-Carlo ``I(m; Z)`` of whole scans, in bits: ``mean`` (``C``) and its standard error
    ``stderr`` (``C``), from ``num_draws`` draws per candidate."""

    mean: torch.Tensor
    stderr: torch.Tensor
    num_draws: int


def scan_information(
    grid: Grid,
    sensor: SensorModel,
    samples,
    candidate_rays: CandidateRays,
    num_draws: int = 256,
    generator: torch.Generator | None = None,
    *,
    weights=None,
    bin_width: float | None = None,
) -> ScanInformation:
    r"""Whole-scan ``I(m; z_new | z)`` in bits by the nested Monte-Carlo estimator of the module docstring.

    Draws ``s_n ~ w`` and ``Z_n ~ p(Z | F_{s_n})`` (all beams of the candidate, the sensor's own sampling
    rule), scores ``log p(Z_n | F_{s_n}) - log sum_s w_s p(Z_n | F_s)``. Continuous readings are scored by
    their density (``bin_width=None``) or by their bin (``bin_width`` cells, as :func:`beam_information`).
    Uniforms and normals are drawn from ``generator`` (torch), so a seed fixes the result.

    Returns:
        :class:`ScanInformation` (``mean`` and ``stderr``, ``C`` each).
    """
    check_rays(grid, candidate_rays)
    reading = _compiled_reading(sensor, bin_width)
    N = int(num_draws)
    if N < 2:
        raise ValueError(f"num_draws must be at least 2 (for a standard error), got {num_draws!r}")
    rays = candidate_rays
    ps = packed_samples(samples, grid.num_cells, weights)
    C, B = rays.num_candidates, rays.num_beams
    g = generator
    u_pick = torch.rand(C, N, generator=g, dtype=torch.float64).numpy()
    eps = torch.randn(C, N, B, generator=g, dtype=torch.float64).numpy()
    u_a = torch.rand(C, N, B, generator=g, dtype=torch.float64).numpy()
    u_b = torch.rand(C, N, B, generator=g, dtype=torch.float64).numpy()
    draws = Draws(u_pick, eps, u_a, u_b)
    mean, var = scan_mi_kernel(ps, ray_table(rays), _ray_F(rays, reading), reading, bin_width is not None, draws)
    refuse_blocked(rays, np.isnan(mean), "every sample")
    return ScanInformation(
        mean=torch.from_numpy(mean / _LN2), stderr=torch.from_numpy(np.sqrt(var / N) / _LN2), num_draws=N
    )
