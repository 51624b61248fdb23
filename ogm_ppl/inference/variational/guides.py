r"""Pyro guides for the occupancy model, so that VI and MCMC can be compared on the same model.

* :class:`MeanFieldGuide` — ``q(m) = prod_k Bernoulli(sigmoid(phi_k))``, one logit per latent cell (the
  family traditional OGM lives in, here fitted to the forward-model posterior instead of amortised).
* :class:`PatchGuide` — a categorical over the ``2^L`` configurations of each non-overlapping patch (the
  patch-map family of Chapter 3, fitted variationally): cells within a patch are correlated.

Both are Pyro guides (``PyroModule`` s) for the site ``"m"`` of :meth:`OccupancyModel.model` (the latent
cells, event shape ``L``) and train with Pyro's ``SVI``: :func:`fit_guide` with ``loss="tracegraph"``
(``TraceGraph_ELBO``, score-function gradients with vectorised particles; the discrete site is not
reparameterisable), ``"rws"`` (``ReweightedWakeSleep``: importance-weighted wake-phi updates, which fit
``KL(p || q)``) or ``"exact"`` (:class:`~ogm_ppl.inference.variational.elbo.ExactELBO`, the ELBO in
closed form where the guide and an independent prior allow it). Each instance has its own parameter
names (``"<name>.logits"``, ``name`` defaulting to ``"<ClassName>_<n>"``, unique in the process). See
:mod:`ogm_ppl.inference.variational.structured_guides` for the first-hit guide, whose family holds the exact 1D
posterior.

Reverse-KL VI needs a likelihood without zeros: under ``GaussianRange(p_rand=0)`` a map with nothing on a
ray that returned a hit is impossible, and every full-support guide samples such maps, so the ELBO is
``-inf``. :func:`fit_guide` refuses such models; use ``p_rand > 0``.
"""

from __future__ import annotations

import itertools
import math
import warnings

import numpy as np
import pyro
import pyro.distributions as dist
import torch
from pyro.distributions.torch_distribution import TorchDistribution
from pyro.nn import PyroModule, PyroParam
from torch.distributions import constraints

from ogm_ppl._rng import keeps_global_rng
from ogm_ppl.inference.tiling import tile_patches
from ogm_ppl.inference.variational.elbo import ExactELBO, mean_field_elbo
from ogm_ppl.models.occupancy import OccupancyModel
from ogm_ppl.progress import Progress, progress_over

__all__ = ["MeanFieldGuide", "PatchGuide", "PatchMapDistribution", "fit_guide", "guide_name"]

_COUNTER = itertools.count()


def guide_name(obj, name: str | None) -> str:
    """``name``, or a fresh ``"<ClassName>_<n>"`` (unique in the process) when ``None``."""
    return f"{type(obj).__name__}_{next(_COUNTER)}" if name is None else str(name)


class MeanFieldGuide(PyroModule):
    """``q(m) = prod_k Bernoulli(sigmoid(phi_k))`` over the latent cells, parameter ``"<name>.logits"``
    (``L``). ``init_logits``: ``K`` (pinned entries ignored) or ``L`` values."""

    def __init__(self, model: OccupancyModel, name: str | None = None, init_logits: torch.Tensor | None = None) -> None:
        super().__init__(guide_name(self, name))
        self.occupancy = model
        K, L = model.num_cells, len(model.latent)
        init = (
            torch.zeros(L, dtype=torch.float64)
            if init_logits is None
            else torch.as_tensor(init_logits, dtype=torch.float64).clone()
        )
        if init.shape == (K,) and K != L:
            init = init[model.latent]
        if init.shape != (L,) or not torch.isfinite(init).all():
            raise ValueError(f"init_logits must be {L} (latent) or {K} finite values, got shape {tuple(init.shape)}")
        self.logits = PyroParam(init)

    @property
    def name(self) -> str:
        return self._pyro_name

    def forward(self, readings=None):
        """Sample site ``"m"``. ``readings``, the model's argument (a Pyro guide takes the model's arguments, as
        ``SVI.step(readings)`` and ``Predictive(..., guide=g)(readings=None)`` pass them), is not used: this
        guide is fitted to one set of readings and does not condition on them."""
        return pyro.sample("m", dist.Bernoulli(logits=self.logits).to_event(1))

    def exact_elbo(self, model: OccupancyModel) -> torch.Tensor:
        """The ELBO in closed form (independent prior, any rays): see :mod:`.elbo`."""
        with self._pyro_context:
            return mean_field_elbo(model, self.logits)

    def marginals(self) -> torch.Tensor:
        """``K`` occupancy probabilities (pinned cells 0)."""
        out = torch.zeros(self.occupancy.num_cells, dtype=torch.float64)
        out[self.occupancy.latent] = torch.sigmoid(self.logits).detach()
        return out


class PatchMapDistribution(TorchDistribution):
    """A distribution over binary maps: independent categoricals over the configurations of
    non-overlapping patches (``P x L`` cell indices, ``-1`` padding); cells in no patch are 0."""

    arg_constraints: dict = {}
    support = constraints.independent(constraints.boolean, 1)

    def __init__(
        self,
        logits: torch.Tensor,
        patches: torch.Tensor,
        num_cells: int,
        cells: torch.Tensor | None = None,
        validate_args=None,
    ):
        self.logits = logits - torch.logsumexp(logits, -1, keepdim=True)  # batch x P x W
        self.patches = patches
        self.num_cells = int(num_cells)
        self.cells = cells  # event cells (e.g. the latent ones); None: all K
        self.bits = (torch.arange(logits.shape[-1])[:, None] >> torch.arange(patches.shape[1])) & 1  # W x L
        n = num_cells if cells is None else len(cells)
        super().__init__(logits.shape[:-2], torch.Size([n]), validate_args=validate_args)

    def expand(self, batch_shape, _instance=None):
        logits = self.logits.expand(torch.Size(batch_shape) + self.logits.shape[-2:])
        return PatchMapDistribution(logits, self.patches, self.num_cells, self.cells)

    def _configs(self, value: torch.Tensor) -> torch.Tensor:
        if self.cells is not None and value.shape[-1] != self.num_cells:
            full = value.new_zeros(value.shape[:-1] + (self.num_cells,))
            full[..., self.cells] = value
            value = full
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
        out = out[..., : self.num_cells]
        return out if self.cells is None else out[..., self.cells]

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


class PatchGuide(PyroModule):
    """Independent categoricals over the configurations of non-overlapping patches (a tiling of runs or
    rectangles, see :func:`~ogm_ppl.inference.tiling.patch_shape`, in which a patch starts at column
    ``offset``), parameter ``"<name>.logits"`` (``P x 2^L``)."""

    def __init__(self, model: OccupancyModel, patch=3, name: str | None = None, offset: int = 0) -> None:
        super().__init__(guide_name(self, name))
        self.occupancy = model
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
        P, W = self.patches.shape[0], 1 << self.L
        # configurations that switch on padding cells are impossible
        live = (self.patches >= 0).sum(1)
        self._valid = (torch.arange(W)[None, :] >> live[:, None]) == 0
        self.logits = PyroParam(torch.zeros(P, W, dtype=torch.float64))

    @property
    def name(self) -> str:
        return self._pyro_name

    def distribution(self) -> PatchMapDistribution:
        with self._pyro_context:
            lg = self.logits
        lg = torch.where(self._valid, lg, torch.tensor(-math.inf, dtype=lg.dtype))
        return PatchMapDistribution(lg, self.patches, self.occupancy.num_cells, self.occupancy.latent)

    def forward(self, readings=None):
        """Sample site ``"m"``. ``readings``, the model's argument (a Pyro guide takes the model's arguments, as
        ``SVI.step(readings)`` and ``Predictive(..., guide=g)(readings=None)`` pass them), is not used: this
        guide is fitted to one set of readings and does not condition on them."""
        return pyro.sample("m", self.distribution())

    def marginals(self) -> torch.Tensor:
        with torch.no_grad():
            return self.distribution().marginals()


@keeps_global_rng
def fit_guide(
    model: OccupancyModel,
    guide,
    steps: int = 1000,
    lr: float = 0.05,
    num_particles: int = 256,
    seed: int = 0,
    progress: bool | Progress = False,
    loss: str = "tracegraph",
) -> list[float]:
    """Train ``guide`` with ``SVI(model.model, guide, Adam(lr), <loss>)``.

    ``loss``: ``"tracegraph"`` (``TraceGraph_ELBO(num_particles, vectorised)``, score-function reverse
    KL), ``"rws"`` (``ReweightedWakeSleep(num_particles)``, wake-phi only: importance-weighted
    ``KL(p || q)``), or ``"exact"`` (:class:`~ogm_ppl.inference.variational.elbo.ExactELBO`, for guides with
    ``exact_elbo``). Returns the loss trace. Seeds Pyro with ``seed`` (any integer ``>= 0``; one of more than 32
    bits, as experiments derive, is folded to the 32 NumPy takes) and leaves the caller's global random streams
    (torch, NumPy, ``random``) as it found them; the guide's parameters live in the guide (a
    ``PyroModule``), so other guides' parameters are untouched. ``progress``: show progress
    (:class:`~ogm_ppl.progress.Progress`), or a caller's own ``Progress`` to update (left open).
    """
    from pyro.infer import SVI, ReweightedWakeSleep, TraceGraph_ELBO
    from pyro.optim import Adam

    valid = torch.arange(model.loglik_table.shape[1])[None, :] <= model.lengths[:, None]
    if loss != "exact" and torch.isinf(model.loglik_table[valid]).any():
        raise ValueError(
            "the model gives some maps zero likelihood (e.g. a hit on a ray with no occupied cell under "
            "GaussianRange(p_rand=0)); KL(q || p) is then infinite for any guide that can sample them. "
            "Use a sensor without zeros, e.g. GaussianRange(sigma, p_rand=1e-3)"
        )
    if loss == "tracegraph":
        objective = TraceGraph_ELBO(num_particles=num_particles, vectorize_particles=True, max_plate_nesting=0)
    elif loss == "rws":
        objective = ReweightedWakeSleep(
            num_particles=num_particles,
            insomnia=1.0,
            model_has_params=False,
            vectorize_particles=True,
            max_plate_nesting=0,
        )
    elif loss == "exact":
        objective = ExactELBO()
    else:
        raise ValueError(f"loss must be 'tracegraph', 'rws' or 'exact', got {loss!r}")
    seed = int(seed)
    if seed < 0:
        raise ValueError(f"seed must be >= 0, got {seed}")
    pyro.set_rng_seed((seed ^ (seed >> 32)) & 0xFFFFFFFF)  # NumPy takes 32 bits: a 64-bit seed is folded in
    svi = SVI(model.model, guide, Adam({"lr": lr}), objective)
    losses = []
    # a bar on a terminal; elsewhere a plain line every 10 s once the fit has taken 10 s
    with progress_over(progress, steps, "svi steps", unit="step") as bar:
        for step in range(steps):
            with warnings.catch_warnings():
                warnings.filterwarnings("ignore", message="Encountered NaN", category=UserWarning)
                out = svi.step()
            value = float(out[1] if isinstance(out, tuple) else out)
            if not math.isfinite(value):
                why = _why_not_finite(model.prior, loss, num_particles)
                raise ValueError(f"fit_guide: the {loss} loss is {value} at step {step + 1}: {why}")
            losses.append(value)
            bar.update()
    return losses


def _why_not_finite(prior, loss: str, num_particles: int) -> str:
    """Why a ``fit_guide`` loss is not finite, and what to do."""
    name = type(prior).__name__
    if not getattr(prior, "can_be_zero", False):
        return "the model's log joint or the guide's log density is not finite on the guide's draws"
    if loss == "rws":
        return (
            f"{name} gives some maps zero mass (can_be_zero) and every one of the {num_particles} draws had zero "
            "mass, so none carries weight; use more particles or a guide that draws maps the prior allows more "
            "often (FirstHitGuide for DataDriven1DPrior)"
        )
    return (
        f"{name} gives some maps zero mass (can_be_zero) and the guide drew such maps, which makes the reverse KL "
        "infinite; use loss='rws' (such draws weigh nothing there) or a strictly positive prior"
    )
