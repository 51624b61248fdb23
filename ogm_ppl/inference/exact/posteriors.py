r"""Exact posteriors (Sections 2.3, 2.3.1, 5.1) and Pyro's own enumeration as a cross-check.

* :func:`brute_force`: all ``2^L`` configurations of the ``L`` latent cells, any rays (1D or 2D), any
  prior; evaluated in chunks of maps so memory stays bounded. Refuses ``L > max_cells``.
* :func:`pose_constrained_1d`: a stationary robot whose readings share one ray. The map enters the
  likelihood only through the first occupied cell ``f``, so the posterior is a distribution over
  ``f`` (``n + 1`` classes) with the cells behind ``f`` left to the prior (Section 2.3.1):

  .. math:: p(f = j \mid z) \propto p(f = j) \prod_n p(z_n \mid f = j)

  with ``p(f = j) = lambda_j prod_{i<j} (1 - lambda_i)`` under an independent prior and ``1 / (n + 1)``
  under the 1D data-driven prior of Section 5.1. Log space throughout, any ``K``.
* :func:`pyro_enumeration`: marginals from Pyro's ``TraceEnum_ELBO.compute_marginals`` on the per-cell
  model (one Bernoulli site per latent cell, enumerated in parallel), for small ``L``.
"""

from __future__ import annotations

import math

import torch

from ogm_ppl.models.occupancy import OccupancyModel
from ogm_ppl.posterior import ChainPosterior1D, WeightedMaps
from ogm_ppl.priors import DataDriven1DPrior, IndependentPrior

__all__ = ["brute_force", "pose_constrained_1d", "pyro_enumeration", "MAX_BRUTE_FORCE_CELLS"]

#: Default limit on latent cells for brute force (2^24 = 16.8 M maps, about a minute).
MAX_BRUTE_FORCE_CELLS = 24


def _bits(codes: torch.Tensor, L: int) -> torch.Tensor:
    return ((codes[:, None] >> torch.arange(L)) & 1).to(torch.float64)


def brute_force(model: OccupancyModel, max_cells: int = MAX_BRUTE_FORCE_CELLS, chunk: int = 1 << 15) -> WeightedMaps:
    """The full Bayesian posterior over all ``2^L`` maps of the latent cells (Eq. 2.5, 2.6).

    Pinned (known-free) cells stay 0. The unnormalised log joint of every map is kept (``2^L`` float64,
    128 MiB at ``L = 24``); statistics re-decode maps in chunks.

    Raises:
        ValueError: ``L > max_cells`` (names the limit), or every map has zero posterior mass.
    """
    latent = model.latent
    L = len(latent)
    if L > max_cells:
        raise ValueError(
            f"brute force over {L} latent cells means 2^{L} maps; the limit is max_cells = {max_cells} "
            f"(raise it knowingly, or use pose_constrained_1d / Gibbs sampling)"
        )
    K = model.num_cells
    n = 1 << L
    log_joint = torch.empty(n, dtype=torch.float64)
    for a in range(0, n, chunk):
        codes = torch.arange(a, min(a + chunk, n), dtype=torch.int64)
        maps = torch.zeros(len(codes), K, dtype=torch.float64)
        maps[:, latent] = _bits(codes, L)
        log_joint[a : a + len(codes)] = model.log_joint(maps)
    if torch.isnan(log_joint).any():
        raise FloatingPointError("log joint is NaN for some map")
    log_z = torch.logsumexp(log_joint, 0)
    if not torch.isfinite(log_z):
        raise ValueError("every map has zero posterior mass: the prior and the readings are incompatible")
    log_post = log_joint - log_z

    def chunks():
        for a in range(0, n, chunk):
            codes = torch.arange(a, min(a + chunk, n), dtype=torch.int64)
            maps = torch.zeros(len(codes), K, dtype=torch.float64)
            maps[:, latent] = _bits(codes, L)
            yield maps, torch.exp(log_post[a : a + len(codes)])

    post = WeightedMaps(model, chunks, n)
    post.log_probs = log_post
    post.log_evidence = float(log_z)
    return post


def _common_ray(model: OccupancyModel) -> torch.Tensor:
    r = model.rays
    first = r.ray(0)
    if not (r.lengths == len(first)).all():
        raise ValueError("pose_constrained_1d needs every reading on the same ray (a stationary robot)")
    cells = r.cells.reshape(r.num_rays, len(first))
    if not (cells == first[None, :]).all():
        raise ValueError("pose_constrained_1d needs every reading on the same ray (a stationary robot)")
    on_ray = torch.zeros(model.num_cells, dtype=torch.bool)
    on_ray[torch.from_numpy(first.copy())] = True
    if not on_ray[model.latent].all():
        raise ValueError("pose_constrained_1d needs every latent cell on the robot's ray")
    return torch.from_numpy(first.copy())


def pose_constrained_1d(model: OccupancyModel) -> ChainPosterior1D:
    """Exact posterior of a stationary robot (Section 2.3.1; Section 5.1 for the data-driven prior).

    Supports :class:`~ogm_ppl.priors.IndependentPrior` (any per-cell ``lambda_``) and
    :class:`~ogm_ppl.priors.DataDriven1DPrior`. Costs ``O(K N)``.
    """
    cells = _common_ray(model)
    n = len(cells)
    pinned = model.known_free[cells]
    ll = model.loglik_table[:, : n + 1].sum(0)  # log prod_n p(z_n | f = j), j = 0..n (n = none)
    prior = model.prior
    if isinstance(prior, IndependentPrior):
        lam = torch.where(pinned, torch.zeros((), dtype=torch.float64), prior.lambda_[cells].to(torch.float64))
        log_on = torch.log(lam)  # -inf on pinned cells
        log_off = torch.log1p(-lam)
        free_before = torch.cat([log_off.new_zeros(1), torch.cumsum(log_off, 0)])  # n + 1
        # pinned cells are free in every map: their prior factor is a constant of the evidence
        pinned_free = torch.log1p(-prior.lambda_[cells][pinned]).sum()
        log_pf_prior = torch.cat([log_on + free_before[:-1], free_before[-1:]]) + pinned_free
        behind = lam
    elif isinstance(prior, DataDriven1DPrior):
        if prior.num_cells != model.num_cells:
            raise ValueError("the prior's cell count differs from the model's")
        if not torch.equal(cells, torch.arange(model.num_cells)):
            raise ValueError("DataDriven1DPrior needs the ray to cover cells 0..K-1 in increasing order")
        pos = torch.arange(n)
        last_pinned = int(pos[pinned].max()) if pinned.any() else -1
        # the wall may start at any cell from the prior's start on, behind every pinned (free) cell
        wall_ok = (pos >= prior.start) & (pos > last_pinned)
        f64 = dict(dtype=torch.float64)  # float64 throughout: where() of bare floats gives float32
        log_pf_prior = torch.cat(
            [torch.where(wall_ok, torch.tensor(0.0, **f64), torch.tensor(-math.inf, **f64)), torch.zeros(1, **f64)]
        )
        log_pf_prior = log_pf_prior - math.log(prior.n + 1)  # each of the n + 1 maps, Fig. 5.1
        behind = torch.ones(n, dtype=torch.float64)
    else:
        raise TypeError(f"pose_constrained_1d supports IndependentPrior and DataDriven1DPrior, not {prior!r}")
    log_joint = log_pf_prior + ll
    log_z = torch.logsumexp(log_joint, 0)
    if not torch.isfinite(log_z):
        raise ValueError("every map has zero posterior mass: the prior and the readings are incompatible")
    post = ChainPosterior1D(model, log_joint - log_z, behind)
    post.log_evidence = float(log_z)
    return post


def pyro_enumeration(model: OccupancyModel, max_cells: int = 16) -> torch.Tensor:
    """Marginals ``p(m_k = 1 | z)`` (``K``) by Pyro's exact discrete enumeration (cross-check)."""
    from pyro.infer import TraceEnum_ELBO

    L = len(model.latent)
    if L > max_cells:
        raise ValueError(f"Pyro enumeration over {L} latent cells exceeds max_cells = {max_cells}")
    elbo = TraceEnum_ELBO(max_plate_nesting=0)  # the model has no parameters: the caller's param store is left alone
    marg = elbo.compute_marginals(model.model_per_cell, lambda: None)
    out = torch.zeros(model.num_cells, dtype=torch.float64)
    for k in model.latent.tolist():
        out[k] = marg[f"m_{k}"].probs  # a Bernoulli; probs stays finite where logits are infinite
    return out
