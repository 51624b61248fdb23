r"""The ELBO in closed form, and :class:`ExactELBO`, a Pyro ``ELBO`` for ``SVI`` that uses it.

Under an independent prior the ELBO of both
:class:`~ogm_ppl.inference.variational.structured_guides.FirstHitGuide` and
:class:`~ogm_ppl.inference.variational.guides.MeanFieldGuide` is a finite sum (Section 2.5):

.. math::
    \mathcal{L}_{FH} = \sum_j q_j \Bigl[\ell_j + \log p(f = j) - \log q_j
        - \sum_{k > j} \mathrm{KL}(\mathrm{Bern}(s_k) \,\|\, \mathrm{Bern}(\lambda_k))\Bigr]

(``ell_j = sum_n log p(z_n | f = j)``), and for the mean field, on any rays,
``E_q log p(z | m) = sum_n sum_j q(f_n = j) log p(z_n | f_n = j)`` with
``q(f_n = j) = q_{c_j} prod_{i < j} (1 - q_{c_i})``. No sampling, no variance, exact gradients.

Here ``q_j`` is the first-hit guide's ``q(f = j)``, ``s_k`` the occupancy of cell ``k`` behind the first
hit and ``lambda_k`` the prior's.
"""

from __future__ import annotations

import math

import torch
import torch.nn.functional as nnf
from pyro.infer import ELBO

from ogm_ppl.models.occupancy import OccupancyModel

__all__ = ["ExactELBO", "first_hit_elbo", "mean_field_elbo"]


def _independent(model: OccupancyModel):
    lo = model.prior.cell_log_odds()
    if lo is None:
        raise TypeError(
            f"the closed-form ELBO needs a prior with independent cells, not {model.prior!r}; "
            "use loss='rws' or 'tracegraph'"
        )
    lo = lo.to(torch.float64)
    log_on, log_off = nnf.logsigmoid(lo), nnf.logsigmoid(-lo)
    return log_on, log_off, log_off[model.known_free].sum()  # pinned cells: free in every map


def _bern_kl_to_prior(logits, log_on, log_off):
    """``E_q log p(m_k) + H(q_k)`` per cell: ``-KL(Bern(q) || Bern(lambda))``."""
    q = torch.sigmoid(logits)
    return q * (log_on - nnf.logsigmoid(logits)) + (1 - q) * (log_off - nnf.logsigmoid(-logits))


def first_hit_elbo(model: OccupancyModel, f_logits, behind_logits, pos, order) -> torch.Tensor:
    """The first-hit guide's ELBO in closed form (module docstring); equals ``log p(z)`` at the optimum.

    ``f_logits``: ``L + 1``; ``behind_logits``: ``L`` (ray order); ``pos``: the ray positions of the
    ``L`` latent cells; ``order``: their latent indices in ray order."""
    log_on, log_off, pinned = _independent(model)
    cells = torch.from_numpy(model.rays.ray(0).copy())
    n = len(cells)
    lat_cells = model.latent[order]  # grid cells of the latent ray positions
    cols = torch.cat([pos, torch.tensor([n])])  # table columns of f = 0..L-1 and "none"
    ll = model.loglik_table[:, cols].sum(0)  # L + 1
    lon, loff = log_on[lat_cells], log_off[lat_cells]
    free_before = torch.cat([loff.new_zeros(1), torch.cumsum(loff, 0)])  # L + 1
    log_pf = free_before + torch.cat([lon, lon.new_zeros(1)])
    per_cell = _bern_kl_to_prior(behind_logits, lon, loff)  # L
    suffix = torch.flip(torch.cumsum(torch.flip(per_cell, [0]), 0), [0])  # sum_{k >= j}
    behind = torch.cat([suffix[1:], per_cell.new_zeros(2)])  # sum_{k > j}, j = 0..L
    lq = f_logits - torch.logsumexp(f_logits, 0)
    q = lq.exp()
    term = torch.where(q > 0, q * (ll + log_pf - lq + behind), 0.0)
    return term.sum() + pinned


def mean_field_elbo(model: OccupancyModel, logits: torch.Tensor) -> torch.Tensor:
    """The mean-field guide's ELBO in closed form, any rays, independent prior (module docstring).

    ``logits``: ``L`` (latent cells)."""
    log_on, log_off, pinned = _independent(model)
    K = model.num_cells
    lat = model.latent
    prior_term = _bern_kl_to_prior(logits, log_on[lat], log_off[lat]).sum() + pinned
    # log q(m_k = 1), log q(m_k = 0) on K + 1 cells (pinned and the padding column: always free)
    lq1 = torch.full((K + 1,), -math.inf, dtype=torch.float64)
    lq0 = torch.zeros(K + 1, dtype=torch.float64)
    lq1 = lq1.index_put((lat,), nnf.logsigmoid(logits))
    lq0 = lq0.index_put((lat,), nnf.logsigmoid(-logits))
    dense = model._dense_rays()  # R x Lmax, padded with K
    a1, a0 = lq1[dense], lq0[dense]
    free_before = torch.cat([a0.new_zeros(len(dense), 1), torch.cumsum(a0, 1)], 1)  # R x (Lmax + 1)
    lpf = free_before[:, :-1] + a1  # q(f_n = j), j < Lmax (padding: -inf)
    lengths = model.lengths
    none = free_before[torch.arange(len(dense)), lengths]  # q(no occupied cell on the ray)
    W = model.loglik_table.shape[1]
    lpf = torch.cat([lpf, torch.full((len(dense), max(W - lpf.shape[1], 0)), -math.inf, dtype=torch.float64)], 1)[:, :W]
    lpf = lpf.scatter(1, lengths[:, None], none[:, None])
    p = lpf.exp()
    # mask the table, not the product: 0 * -inf in the padding would make the gradient NaN
    ll = (p * torch.where(p > 0, model.loglik_table, 0.0)).sum()
    return ll + prior_term


class ExactELBO(ELBO):
    """The ELBO in closed form for guides with ``exact_elbo(model)``
    (:class:`~ogm_ppl.inference.variational.structured_guides.FirstHitGuide`,
    :class:`~ogm_ppl.inference.variational.guides.MeanFieldGuide`) on an :class:`OccupancyModel` with an
    independent prior: use as ``SVI(model.model, guide, optim, ExactELBO())``. Deterministic and exact."""

    def __init__(self):
        super().__init__(num_particles=1)

    @staticmethod
    def _occupancy(model) -> OccupancyModel:
        occ = getattr(model, "__self__", None)
        if not isinstance(occ, OccupancyModel):
            raise TypeError("ExactELBO needs the bound method OccupancyModel.model as its model")
        return occ

    def _get_trace(self, model, guide, args, kwargs):  # pragma: no cover - no traces: closed form
        raise NotImplementedError

    def differentiable_loss(self, model, guide, *args, **kwargs):
        if not hasattr(guide, "exact_elbo"):
            raise TypeError(f"ExactELBO needs a guide with exact_elbo(model), not {type(guide).__name__}")
        return -guide.exact_elbo(self._occupancy(model))

    def loss(self, model, guide, *args, **kwargs):
        with torch.no_grad():
            return float(self.differentiable_loss(model, guide, *args, **kwargs))

    def loss_and_grads(self, model, guide, *args, **kwargs):
        loss = self.differentiable_loss(model, guide, *args, **kwargs)
        loss.backward()
        return float(loss.detach())
