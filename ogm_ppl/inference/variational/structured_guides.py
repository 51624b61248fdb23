r"""A guide whose family holds the exact 1D posterior, and the ELBO in closed form.

**First-hit guide** (:class:`FirstHitGuide`). On a common ray (a stationary robot, as
:func:`~ogm_ppl.inference.exact.posteriors.pose_constrained_1d` needs) the map enters the likelihood only through
the first occupied cell ``f``. The guide is the posterior's own structure (Section 2.3.1):

.. math:: q(m) = q(f(m)) \prod_{k > f(m)} \mathrm{Bernoulli}(m_k; \sigma(\psi_k))

a categorical over the ``L + 1`` first hits (the latent cells in ray order, and "none"), cells before
``f`` free, cells behind it independent. Under an independent prior the exact posterior is
``q(f) = p(f | z)``, ``sigma(psi_k) = lambda_k``: inside the family.

**Exact ELBO** (:class:`ExactELBO`, a Pyro ``ELBO`` for ``SVI``). Under an independent prior the ELBO of
both the first-hit guide and :class:`~ogm_ppl.inference.variational.guides.MeanFieldGuide` is a finite sum:

.. math::
    \mathcal{L}_{FH} = \sum_j q_j \Bigl[\ell_j + \log p(f = j) - \log q_j
        - \sum_{k > j} \mathrm{KL}(\mathrm{Bern}(s_k) \,\|\, \mathrm{Bern}(\lambda_k))\Bigr]

(``ell_j = sum_n log p(z_n | f = j)``), and for the mean field, on any rays,
``E_q log p(z | m) = sum_n sum_j q(f_n = j) log p(z_n | f_n = j)`` with
``q(f_n = j) = q_{c_j} prod_{i < j} (1 - q_{c_i})``. No sampling, no variance, exact gradients.

>>> from ogm_ppl import GaussianRange, OccupancyModel, raycast
>>> from ogm_ppl.datasets import toy_1d, THESIS_TOY_READINGS
>>> from ogm_ppl.priors import IndependentPrior
>>> from ogm_ppl.inference.variational.guides import fit_guide
>>> toy = toy_1d(num_cells=21, readings=THESIS_TOY_READINGS)
>>> model = OccupancyModel(toy.grid, raycast(toy.grid, toy.scans), GaussianRange(3.0, 1e-3), IndependentPrior(0.5, 21))
>>> guide = FirstHitGuide(model)
>>> _ = fit_guide(model, guide, steps=50, lr=0.1, loss="exact")
>>> guide.marginals().shape
torch.Size([21])
"""

from __future__ import annotations

import math

import pyro
import torch
import torch.nn.functional as nnf
from pyro.distributions.torch_distribution import TorchDistribution
from pyro.infer import ELBO
from pyro.nn import PyroModule, PyroParam
from torch.distributions import constraints

from ogm_ppl.inference.variational.guides import guide_name
from ogm_ppl.models.occupancy import OccupancyModel

__all__ = ["FirstHitGuide", "FirstHitMapDistribution", "ExactELBO", "mean_field_elbo", "first_hit_elbo"]


class FirstHitMapDistribution(TorchDistribution):
    """``q(m) = q(f) prod_{k > f} Bernoulli(m_k; sigmoid(psi_k))`` over ``L`` cells (event shape ``L``).

    Args:
        f_logits: ``... x (L + 1)`` logits of the first hit (position ``0..L-1`` in ``order``, ``L``: none).
        behind_logits: ``... x L`` logits of the cells behind the first hit, in ray order.
        order: ``L`` indices into the event: the cells in ray order.
    """

    arg_constraints: dict = {}
    support = constraints.independent(constraints.boolean, 1)

    def __init__(self, f_logits, behind_logits, order, validate_args=None):
        self.f_logits = f_logits - torch.logsumexp(f_logits, -1, keepdim=True)
        self.behind_logits = behind_logits
        self.order = order
        batch = torch.broadcast_shapes(f_logits.shape[:-1], behind_logits.shape[:-1])
        super().__init__(batch, torch.Size([len(order)]), validate_args=validate_args)

    def expand(self, batch_shape, _instance=None):
        b = torch.Size(batch_shape)
        return FirstHitMapDistribution(self.f_logits.expand(b + self.f_logits.shape[-1:]),
                                       self.behind_logits.expand(b + self.behind_logits.shape[-1:]), self.order)  # fmt: skip

    def sample(self, sample_shape=torch.Size()):
        shape = torch.Size(sample_shape) + self.batch_shape
        L = len(self.order)
        with torch.no_grad():
            j = torch.distributions.Categorical(logits=self.f_logits.expand(shape + (L + 1,))).sample()
            b = torch.distributions.Bernoulli(logits=self.behind_logits.expand(shape + (L,))).sample()
            pos = torch.arange(L)
            x = torch.where(pos < j[..., None], 0.0, torch.where(pos == j[..., None], 1.0, b))
            out = torch.empty_like(x)
            out[..., self.order] = x
        return out

    def log_prob(self, value):
        x = value[..., self.order]
        L = len(self.order)
        occ = x != 0
        j = torch.where(occ.any(-1), occ.to(torch.uint8).argmax(-1), L)
        lf = torch.gather(self.f_logits.expand(x.shape[:-1] + (L + 1,)), -1, j[..., None])[..., 0]
        lb = -nnf.binary_cross_entropy_with_logits(self.behind_logits.expand(x.shape), x.to(self.behind_logits.dtype),
                                                   reduction="none")  # fmt: skip
        behind = torch.arange(L) > j[..., None]
        return lf + torch.where(behind, lb, 0.0).sum(-1)

    def marginals(self) -> torch.Tensor:
        """``... x L`` occupancy probabilities (event order)."""
        qf = self.f_logits.exp()[..., :-1]
        before = torch.cumsum(qf, -1) - qf  # P(f < k)
        x = qf + before * torch.sigmoid(self.behind_logits)
        out = torch.empty_like(x)
        out[..., self.order] = x
        return out


def _ray_order(model: OccupancyModel):
    """Latent cells in ray order on a common ray: (positions along the ray ``L``, latent indices ``L``)."""
    from ogm_ppl.inference.exact.posteriors import _common_ray

    cells = _common_ray(model)  # raises unless every reading shares one ray holding every latent cell
    lat_index = torch.full((model.num_cells,), -1, dtype=torch.long)
    lat_index[model.latent] = torch.arange(len(model.latent))
    pos = torch.nonzero(~model.known_free[cells]).flatten()
    return pos, lat_index[cells[pos]]


class FirstHitGuide(PyroModule):
    """The first-hit guide on a common ray (module docstring): parameters ``"<name>.f_logits"``
    (``L + 1``) and ``"<name>.behind_logits"`` (``L``, ray order)."""

    def __init__(self, model: OccupancyModel, name: str | None = None) -> None:
        super().__init__(guide_name(self, name))
        self.occupancy = model
        self._pos, self._order = _ray_order(model)
        L = len(self._order)
        self.f_logits = PyroParam(torch.zeros(L + 1, dtype=torch.float64))
        self.behind_logits = PyroParam(torch.zeros(L, dtype=torch.float64))

    @property
    def name(self) -> str:
        return self._pyro_name

    def distribution(self) -> FirstHitMapDistribution:
        with self._pyro_context:
            return FirstHitMapDistribution(self.f_logits, self.behind_logits, self._order)

    def forward(self):
        return pyro.sample("m", self.distribution())

    def exact_elbo(self, model: OccupancyModel) -> torch.Tensor:
        with self._pyro_context:
            return first_hit_elbo(model, self.f_logits, self.behind_logits, self._pos, self._order)

    def marginals(self) -> torch.Tensor:
        """``K`` occupancy probabilities (pinned cells 0)."""
        out = torch.zeros(self.occupancy.num_cells, dtype=torch.float64)
        with torch.no_grad():
            out[self.occupancy.latent] = self.distribution().marginals()
        return out


def _independent(model: OccupancyModel):
    lo = model.prior.cell_log_odds()
    if lo is None:
        raise TypeError(f"the closed-form ELBO needs a prior with independent cells, not {model.prior!r}; "
                        "use loss='rws' or 'tracegraph'")  # fmt: skip
    lo = lo.to(torch.float64)
    log_on, log_off = nnf.logsigmoid(lo), nnf.logsigmoid(-lo)
    return log_on, log_off, log_off[model.known_free].sum()  # pinned cells: free in every map


def _bern_kl_to_prior(logits, log_on, log_off):
    """``E_q log p(m_k) + H(q_k)`` per cell: ``-KL(Bern(q) || Bern(lambda))``."""
    q = torch.sigmoid(logits)
    return q * (log_on - nnf.logsigmoid(logits)) + (1 - q) * (log_off - nnf.logsigmoid(-logits))


def first_hit_elbo(model: OccupancyModel, f_logits, behind_logits, pos, order) -> torch.Tensor:
    """The first-hit guide's ELBO in closed form (module docstring); equals ``log p(z)`` at the optimum."""
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
    """The ELBO in closed form for guides with ``exact_elbo(model)`` (:class:`FirstHitGuide`,
    :class:`~ogm_ppl.inference.variational.guides.MeanFieldGuide`) on an :class:`OccupancyModel` with an independent
    prior: use as ``SVI(model.model, guide, optim, ExactELBO())``. Deterministic and exact."""

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
