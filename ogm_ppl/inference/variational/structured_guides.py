r"""A guide whose family holds the exact 1D posterior.

**First-hit guide** (:class:`FirstHitGuide`). On a common ray (a stationary robot, as
:func:`~ogm_ppl.inference.exact.posteriors.pose_constrained_1d` needs) the map enters the likelihood only through
the first occupied cell ``f``. The guide is the posterior's own structure (Section 2.3.1):

.. math:: q(m) = q(f(m)) \prod_{k > f(m)} \mathrm{Bernoulli}(m_k; \sigma(\psi_k))

a categorical over the ``L + 1`` first hits (the latent cells in ray order, and "none"), cells before
``f`` free, cells behind it independent. Under an independent prior the exact posterior is
``q(f) = p(f | z)``, ``sigma(psi_k) = lambda_k``: inside the family.

Its ELBO under an independent prior is a finite sum,
:func:`~ogm_ppl.inference.variational.elbo.first_hit_elbo` (fitted with ``loss="exact"``,
:class:`~ogm_ppl.inference.variational.elbo.ExactELBO`).

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

import pyro
import torch
import torch.nn.functional as nnf
from pyro.distributions.torch_distribution import TorchDistribution
from pyro.nn import PyroModule, PyroParam
from torch.distributions import constraints

from ogm_ppl.inference.variational.elbo import ExactELBO, first_hit_elbo, mean_field_elbo
from ogm_ppl.inference.variational.guides import guide_name
from ogm_ppl.models.occupancy import OccupancyModel

# ExactELBO and the closed-form ELBOs live in .elbo and are re-exported here
__all__ = ["ExactELBO", "FirstHitGuide", "FirstHitMapDistribution", "first_hit_elbo", "mean_field_elbo"]


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
        return FirstHitMapDistribution(
            self.f_logits.expand(b + self.f_logits.shape[-1:]),
            self.behind_logits.expand(b + self.behind_logits.shape[-1:]),
            self.order,
        )

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
        lb = -nnf.binary_cross_entropy_with_logits(
            self.behind_logits.expand(x.shape), x.to(self.behind_logits.dtype), reduction="none"
        )
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

    try:
        cells = _common_ray(model)  # raises unless every reading shares one ray holding every latent cell
    except ValueError as e:
        raise ValueError(
            f"FirstHitGuide models one ray: every reading on the same ray, holding every latent cell (a 1D map "
            f"seen by a stationary robot); this model has {model.rays.num_rays} rays that do not ({e})"
        ) from None
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

    def forward(self, readings=None):
        """Sample site ``"m"``. ``readings``, the model's argument (a Pyro guide takes the model's arguments, as
        ``SVI.step(readings)`` and ``Predictive(..., guide=g)(readings=None)`` pass them), is not used: this
        guide is fitted to one set of readings and does not condition on them."""
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
