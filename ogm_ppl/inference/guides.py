r"""Pyro guides for the occupancy model, so that VI and MCMC can be compared on the same model.

* :class:`MeanFieldGuide` — ``q(m) = prod_k Bernoulli(sigmoid(phi_k))``, one logit per latent cell (the
  family traditional OGM lives in, here fitted to the forward-model posterior instead of amortised).
* :class:`PatchGuide` — a categorical over the ``2^L`` configurations of each non-overlapping patch (the
  patch-map family of Chapter 3, fitted variationally): cells within a patch are correlated.

Both are Pyro guides for the site ``"m"`` of :meth:`OccupancyModel.model` and train with Pyro's
``SVI`` and ``TraceGraph_ELBO`` (score-function gradients with vectorised particles; the discrete site is
not reparameterisable): :func:`fit_guide`. Pinned (known-free) cells are fixed free.

Reverse-KL VI needs a likelihood without zeros: under ``GaussianRange(p_rand=0)`` a map with nothing on a
ray that returned a hit is impossible, and every full-support guide samples such maps, so the ELBO is
``-inf``. :func:`fit_guide` refuses such models; use ``p_rand > 0``.
"""

from __future__ import annotations

import math

import numpy as np
import pyro
import pyro.distributions as dist
import torch
from pyro.distributions.torch_distribution import TorchDistribution
from torch.distributions import constraints

from ..models.occupancy import OccupancyModel
from .patch_map import tile_patches

__all__ = ["MeanFieldGuide", "PatchGuide", "PatchMapDistribution", "fit_guide"]

_PINNED_LOGIT = -40.0


class MeanFieldGuide:
    """``q(m) = prod_k Bernoulli(sigmoid(phi_k))`` with parameter ``"<name>.logits"``."""

    def __init__(self, model: OccupancyModel, name: str = "mf", init_logits: torch.Tensor | None = None) -> None:
        self.model = model
        self.name = name
        K = model.num_cells
        self.init = torch.zeros(K, dtype=torch.float64) if init_logits is None else torch.as_tensor(init_logits, dtype=torch.float64).clone()

    def logits(self) -> torch.Tensor:
        phi = pyro.param(f"{self.name}.logits", self.init)
        return torch.where(self.model.known_free, torch.tensor(_PINNED_LOGIT, dtype=phi.dtype), phi)

    def __call__(self):
        return pyro.sample("m", dist.Bernoulli(logits=self.logits()).to_event(1))

    def marginals(self) -> torch.Tensor:
        return torch.sigmoid(self.logits()).detach()


class PatchMapDistribution(TorchDistribution):
    """A distribution over binary maps: independent categoricals over the configurations of
    non-overlapping patches (``P x L`` cell indices, ``-1`` padding); cells in no patch are 0."""

    arg_constraints: dict = {}
    support = constraints.independent(constraints.boolean, 1)

    def __init__(self, logits: torch.Tensor, patches: torch.Tensor, num_cells: int, validate_args=None):
        self.logits = logits - torch.logsumexp(logits, -1, keepdim=True)  # batch x P x W
        self.patches = patches
        self.num_cells = int(num_cells)
        self.bits = (torch.arange(logits.shape[-1])[:, None] >> torch.arange(patches.shape[1])) & 1  # W x L
        super().__init__(logits.shape[:-2], torch.Size([num_cells]), validate_args=validate_args)

    def expand(self, batch_shape, _instance=None):
        logits = self.logits.expand(torch.Size(batch_shape) + self.logits.shape[-2:])
        return PatchMapDistribution(logits, self.patches, self.num_cells)

    def _configs(self, value: torch.Tensor) -> torch.Tensor:
        live = self.patches >= 0
        cells = self.patches.clamp(min=0)
        v = value[..., cells].long() * live  # ... x P x L
        return (v << torch.arange(self.patches.shape[1])).sum(-1)  # ... x P

    def sample(self, sample_shape=torch.Size()):
        shape = torch.Size(sample_shape) + self.batch_shape
        w = torch.distributions.Categorical(logits=self.logits.expand(shape + self.logits.shape[-2:])).sample()
        bits = self.bits[w]  # shape x P x L
        out = torch.zeros(shape + (self.num_cells + 1,), dtype=torch.float64)
        idx = torch.where(self.patches >= 0, self.patches, self.num_cells).expand(shape + self.patches.shape)
        out.scatter_(-1, idx.reshape(shape + (-1,)), bits.reshape(shape + (-1,)).to(torch.float64))
        return out[..., : self.num_cells]

    def log_prob(self, value):
        w = self._configs(value)
        lp = torch.gather(self.logits.expand(w.shape + self.logits.shape[-1:]), -1, w[..., None])[..., 0]
        return lp.sum(-1)

    def marginals(self) -> torch.Tensor:
        p = self.logits.exp()  # P x W
        per = p @ self.bits.to(p.dtype)  # P x L
        out = torch.zeros(self.num_cells + 1, dtype=torch.float64)
        idx = torch.where(self.patches >= 0, self.patches, self.num_cells)
        out.scatter_(0, idx.flatten(), per.flatten())
        return out[: self.num_cells]


class PatchGuide:
    """Independent categoricals over the configurations of non-overlapping patches (a tiling of runs or
    rectangles, see :func:`~ogm_ppl.inference.gibbs.patch_shape`, in which a patch starts at column
    ``offset``), parameter ``"<name>.logits"``."""

    def __init__(self, model: OccupancyModel, patch=3, name: str = "patch", offset: int = 0) -> None:
        self.model = model
        self.name = name
        try:
            tiles = tile_patches(model, patch, offset)
        except ValueError as e:
            raise ValueError(f"PatchGuide needs a tiling without overlaps: {e}") from None
        # live cells first, so that configuration bits count only them
        live_first = np.full_like(tiles, -1)
        for i, row in enumerate(tiles):
            live = row[row >= 0]
            live_first[i, : len(live)] = live
        self.patches = torch.from_numpy(live_first)
        self.L = self.patches.shape[1]

    def _logits(self) -> torch.Tensor:
        P, W = self.patches.shape[0], 1 << self.L
        init = torch.zeros(P, W, dtype=torch.float64)
        # configurations that switch on padding cells are impossible
        live = (self.patches >= 0).sum(1)
        w = torch.arange(W)
        valid = (w[None, :] >> live[:, None]) == 0
        lg = pyro.param(f"{self.name}.logits", init)
        return torch.where(valid, lg, torch.tensor(-math.inf, dtype=lg.dtype))

    def distribution(self) -> PatchMapDistribution:
        return PatchMapDistribution(self._logits(), self.patches, self.model.num_cells)

    def __call__(self):
        return pyro.sample("m", self.distribution())

    def marginals(self) -> torch.Tensor:
        with torch.no_grad():
            return self.distribution().marginals()


def fit_guide(model: OccupancyModel, guide, steps: int = 1000, lr: float = 0.05, num_particles: int = 256,
              seed: int = 0, progress: bool = False) -> list[float]:  # fmt: skip
    """Train ``guide`` with ``SVI(model.model, guide, Adam(lr), TraceGraph_ELBO(num_particles, vectorised))``.

    Returns the ELBO loss trace. Clears Pyro's parameter store first and seeds Pyro.
    """
    from pyro.infer import SVI, TraceGraph_ELBO
    from pyro.optim import Adam
    from tqdm.auto import tqdm

    valid = torch.arange(model.loglik_table.shape[1])[None, :] <= model.lengths[:, None]
    if torch.isinf(model.loglik_table[valid]).any():
        raise ValueError(
            "the model gives some maps zero likelihood (e.g. a hit on a ray with no occupied cell under "
            "GaussianRange(p_rand=0)); KL(q || p) is then infinite for any guide that can sample them. "
            "Use a sensor without zeros, e.g. GaussianRange(sigma, p_rand=1e-3)"
        )
    pyro.clear_param_store()
    pyro.set_rng_seed(seed)
    svi = SVI(model.model, guide, Adam({"lr": lr}),
              TraceGraph_ELBO(num_particles=num_particles, vectorize_particles=True, max_plate_nesting=0))  # fmt: skip
    losses = []
    for _ in tqdm(range(steps), disable=not progress, desc="svi"):
        losses.append(float(svi.step()))
    return losses
