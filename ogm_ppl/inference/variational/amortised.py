r"""Amortised inference compiled from the model: a neural guide ``q(m | z)`` over 2D maps (inference
compilation, Le, Baydin and Wood 2017; Pyro's ``CSIS``).

Traditional OGM with a fitted update term (Section 2.5) is already an *amortised* mean-field posterior: one
function of the readings, fitted once, gives ``q(m | z) = prod_k Bernoulli(sigmoid(l_k))`` for any data.
Its update of cell ``k`` sees only the readings whose ray crosses ``k``. :class:`AmortisedGuide` keeps the
mean-field family but lets every cell's logit depend on the evidence around it (and on the prior's
structure) through a small fully convolutional network:

.. math::
    q_\phi(m \mid z) = \prod_{k \in \text{latent}} \mathrm{Bernoulli}\bigl(m_k;\
        \sigma(g_\phi(x(z))_k)\bigr),

where ``x(z)`` rasterises the readings per cell (:func:`evidence_features`: pass-through and hit counts,
the hit share, the p21 evidence grid of Section 2.4/2.5, the observed and pinned masks, and the tile
phase of a patch prior, Section 5.2.2) and ``g_phi`` is a stack of 3 x 3 convolutions (any grid size).

**Training (inference compilation).** The guide is fitted to the model's own joint: maps from the prior
and readings simulated by the forward sensor model, ``(m, z) ~ p(m) p(z | m)`` (Section 2.1, 2.6), with

.. math::
    \mathcal{L}(\phi) = \mathbb{E}_{p(m, z)}\bigl[-\log q_\phi(m \mid z)\bigr]
        = \mathbb{E}_{p(z)}\bigl[\mathrm{KL}(p(m \mid z) \,\|\, q_\phi(m \mid z))\bigr] + \text{const},

the forward (inclusive) KL averaged over data: it needs no posterior samples and no likelihood
evaluations, only simulation (Le et al. 2017, Eq. 4). For a mean-field ``q`` its minimiser at each ``z`` is
the posterior's marginals, the quantity the thesis's maps report (Chapter 4, Eq. 4.6). The training
function is :func:`ogm_ppl.learn.train_prior_guide`; :meth:`AmortisedGuide.csis_loss` is the batch
estimate, and ``pyro.infer.CSIS(model.model, guide, ...)`` trains the same objective one trace at a time
(the guide takes ``observations={"z": ...}``).

**Three uses.** :meth:`AmortisedGuide.marginals` is a one-pass map estimate; :func:`guide_initial_map`
starts Gibbs (Chapter 4) near the posterior; and because ``log q(m | z)`` is exact and cheap, the guide is
an independence Metropolis-Hastings proposal inside Gibbs sweeps that keeps the exact posterior
stationary (:class:`~ogm_ppl.inference.mcmc.guided.GuidedGibbs`, data-driven MCMC).

**Artefacts.** :meth:`AmortisedGuide.save` writes a plain ``.npz`` (no pickle): the architecture fields and
one float32 array per weight. :meth:`AmortisedGuide.load` validates every field (types, ranges, the
weight names and shapes the architecture implies, finite values) and raises :class:`GuideFileError`
naming the path and what is wrong; loading into an existing guide of another architecture is refused
the same way. The trained guide ships as ``ogm_ppl/fitted/guide_amortised.npz`` (:func:`shipped_guide`)
with a JSON sidecar of its training settings and held-out loss.
"""

from __future__ import annotations

import json
import math
import os
import warnings
from dataclasses import asdict, dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np
import pyro
import pyro.distributions as dist
import torch
from pyro.nn import PyroModule
from pyro.nn.module import to_pyro_module_
from torch import nn

from ogm_ppl.grid import Grid
from ogm_ppl.inference.variational.guides import guide_name
from ogm_ppl.io import atomic_write, read_npz
from ogm_ppl.models.occupancy import OBSERVED, OccupancyModel
from ogm_ppl.priors.base import MapPrior
from ogm_ppl.sensors import SensorModel

__all__ = [
    "AmortisedGuide",
    "GuideArchitecture",
    "GuideFileError",
    "evidence_features",
    "feature_names",
    "guide_initial_map",
    "shipped_guide",
    "corpus_guide",
    "corpus_guide_path",
    "corpus_guides",
    "unknown_corpus_message",
    "SHIPPED_GUIDE",
    "Scene",
    "random_scene",
    "FORMAT",
    "FEATURE_VERSION",
]

#: artefact format (bumped when the file layout changes)
FORMAT = 1
#: feature set of :func:`evidence_features` (bumped when a channel changes meaning)
FEATURE_VERSION = 1
_KIND = "ogm_ppl.amortised_guide"
SHIPPED_GUIDE = Path(__file__).resolve().parent.parent.parent / "fitted" / "guide_amortised.npz"
_BASE_FEATURES = ("pass_count", "hit_count", "hit_share", "log_odds", "observed", "pinned", "inside")
_LOGODDS_CLIP = 12.0
_MAX_CHANNELS, _MAX_LAYERS, _MAX_DILATION, _MAX_PHASE = 256, 16, 16, 16


# --------------------------------------------------------------------------------------- features
@lru_cache(maxsize=8)
def _delta(name: str):
    from ogm_ppl.models.delta import delta_by_name

    d = delta_by_name(name)
    if d is None:
        raise ValueError(f"unknown Delta {name!r} for the log-odds feature")
    return d


def feature_names(phase: tuple[int, int] = (3, 3)) -> list[str]:
    """Channel names of :func:`evidence_features` for a tile phase ``(h, w)`` (``(0, 0)``: none)."""
    h, w = phase
    return list(_BASE_FEATURES) + [f"row_mod_{h}={i}" for i in range(h)] + [f"col_mod_{w}={j}" for j in range(w)]


def evidence_features(
    model: OccupancyModel, readings: torch.Tensor | None = None, delta: str = "p21", phase: tuple[int, int] = (3, 3)
) -> torch.Tensor:
    r"""The readings rasterised per cell: ``C x rows x cols`` float32 (``... x C x rows x cols`` for a
    batch of readings ``... x R``; default the model's own readings).

    With ``kappa(z_n)`` the reading's kappa on its ray (:meth:`OccupancyModel.range_to_kappa`, the range
    convention of :mod:`ogm_ppl.raycast`), cell ``k`` gets

    * ``log(1 + #pass)``: rays entering ``k`` before their reading (every cell of a max-range ray);
    * ``log(1 + #hit)``: rays whose reading falls in ``k``; the hit share ``#hit / (#hit + #pass)``;
    * the evidence grid of Eq. (2.10) with update term ``delta`` (default the fitted p21, Section 2.5),
      ``l_k = sum_n Delta(kappa_{n,k}; z_n)``, clipped to +-12 and divided by 4;
    * observed (any ray entered ``k``), pinned (``model.known_free``) and inside (all ones: zero padding
      of the convolutions then marks the grid edge);
    * the tile phase ``(row mod h, col mod w)`` one-hot (``phase = (0, 0)``: none), so that a guide can
      learn the tiling of a patch-table prior (Section 5.2.2), whose tiles start at the grid origin.

    1D grids are one row.
    """
    r = model.rays
    R, K = r.num_rays, model.num_cells
    z = model.readings if readings is None else torch.as_tensor(readings, dtype=torch.float64)
    if z.dim() == 0 or z.shape[-1] != R:
        raise ValueError(f"readings must hold one range per ray ({R}), got shape {tuple(z.shape)}")
    if torch.isnan(z).any():
        raise ValueError("readings hold NaN")
    batch = z.shape[:-1]
    z = z.reshape(-1, R)
    B = z.shape[0]
    F = torch.from_numpy(r.max_range_cells()).to(torch.float64)
    is_max = z >= F
    kz = model.range_to_kappa(z)  # B x R
    ray = torch.from_numpy(r.ray_of_entry)
    kap = torch.from_numpy(r.kappa)
    cells = torch.from_numpy(r.cells)
    kze, mx = kz[:, ray], is_max[:, ray]  # B x nnz
    passed = ((kap[None] < kze) | mx).to(torch.float64)
    hit = ((kap[None] == kze) & ~mx).to(torch.float64)
    n_pass = torch.zeros(B, K, dtype=torch.float64).index_add_(1, cells, passed)
    n_hit = torch.zeros(B, K, dtype=torch.float64).index_add_(1, cells, hit)
    # the evidence grid, as ogm_ppl.inference.log_odds.evidence_grid builds it (delta_table_for)
    n_kappa = int(r.lengths.max())
    hz = kz[~is_max]
    n_z = max(int(hz.max()) + 1 if hz.numel() else 0, n_kappa)
    with torch.no_grad():
        table = _delta(delta).table(n_kappa, n_z).to(torch.float64)
    col = torch.where(mx, n_z, kze)
    lo = torch.zeros(B, K, dtype=torch.float64).index_add_(1, cells, table[kap[None].expand_as(col), col])
    seen = (n_pass + n_hit) > 0
    share = torch.where(seen, n_hit / (n_hit + n_pass).clamp(min=1), 0.0)
    pinned = model.known_free.to(torch.float64).expand(B, K)
    chans = [
        torch.log1p(n_pass),
        torch.log1p(n_hit),
        share,
        lo.clamp(-_LOGODDS_CLIP, _LOGODDS_CLIP) / 4,
        seen.to(torch.float64),
        pinned,
        torch.ones(B, K, dtype=torch.float64),
    ]
    g = model.grid
    rows, cols = (g.rows, g.cols) if g.ndim == 2 else (1, g.num_cells)
    x = torch.stack(chans, 1).reshape(B, len(chans), rows, cols)
    h, w = (int(v) for v in phase)
    if h and w:
        ri = torch.arange(rows) % h
        ci = torch.arange(cols) % w
        oh_r = (ri[None, :, None] == torch.arange(h)[:, None, None]).expand(h, rows, cols)
        oh_c = (ci[None, None, :] == torch.arange(w)[:, None, None]).expand(w, rows, cols)
        ph = torch.cat([oh_r, oh_c]).to(torch.float64)
        x = torch.cat([x, ph[None].expand(B, -1, -1, -1)], 1)
    return x.to(torch.float32).reshape(*batch, x.shape[1], rows, cols)


# --------------------------------------------------------------------------------------- network
@dataclass(frozen=True)
class GuideArchitecture:
    """What fixes the network's weights' names and shapes (validated; stored in every artefact).

    Attributes:
        channels: hidden channels of every 3 x 3 convolution.
        dilations: one 3 x 3 convolution (ReLU after it) per entry, with that dilation; the receptive
            field is ``1 + 2 * sum(dilations)`` cells.
        phase: tile phase features ``(h, w)`` (``(0, 0)``: none).
        delta: the update term of the log-odds feature (a :func:`~ogm_ppl.models.delta.delta_by_name`).
    """

    channels: int = 16
    dilations: tuple[int, ...] = (1, 2, 4, 1)
    phase: tuple[int, int] = (3, 3)
    delta: str = "p21"

    def __post_init__(self) -> None:
        problems = _architecture_problems(self.channels, self.dilations, self.phase, self.delta)
        if problems:
            raise ValueError(f"bad guide architecture: {problems}")
        object.__setattr__(self, "channels", int(self.channels))
        object.__setattr__(self, "dilations", tuple(int(d) for d in self.dilations))
        object.__setattr__(self, "phase", tuple(int(p) for p in self.phase))

    @property
    def in_channels(self) -> int:
        return len(_BASE_FEATURES) + (self.phase[0] + self.phase[1] if self.phase[0] and self.phase[1] else 0)

    @property
    def receptive_field(self) -> int:
        return 1 + 2 * sum(self.dilations)


def _is_int(v) -> bool:
    return isinstance(v, (int, np.integer)) and not isinstance(v, (bool, np.bool_))


def _architecture_problems(channels, dilations, phase, delta) -> str:
    if not _is_int(channels) or not 1 <= channels <= _MAX_CHANNELS:
        return f"channels must be an integer in 1..{_MAX_CHANNELS}, got {channels!r}"
    try:
        dil = tuple(dilations)
    except TypeError:
        return f"dilations must be a sequence of integers, got {dilations!r}"
    if not 1 <= len(dil) <= _MAX_LAYERS or not all(_is_int(d) and 1 <= d <= _MAX_DILATION for d in dil):
        return f"dilations must be 1..{_MAX_LAYERS} integers in 1..{_MAX_DILATION}, got {dilations!r}"
    try:
        ph = tuple(phase)
    except TypeError:
        return f"phase must be (h, w), got {phase!r}"
    if len(ph) != 2 or not all(_is_int(p) and 0 <= p <= _MAX_PHASE for p in ph) or (ph[0] == 0) != (ph[1] == 0):
        return f"phase must be (h, w) with both in 1..{_MAX_PHASE}, or (0, 0), got {phase!r}"
    if not isinstance(delta, str):
        return f"delta must be a name, got {delta!r}"
    try:
        _delta(delta)
    except (ValueError, KeyError, TypeError) as e:
        return f"delta {delta!r} is not a known update term ({e})"
    return ""


class GuideNet(nn.Module):
    """Fully convolutional logits: ``3 x 3`` convolutions with ReLU (zero padding, so any grid size),
    a ``1 x 1`` head, plus a ``1 x 1`` linear skip from the features. ``B x C x H x W -> B x H x W``."""

    def __init__(self, arch: GuideArchitecture) -> None:
        super().__init__()
        c_in, c = arch.in_channels, arch.channels
        convs = []
        for d in arch.dilations:
            convs.append(nn.Conv2d(c_in, c, 3, padding=d, dilation=d, dtype=torch.float32))
            c_in = c
        self.convs = nn.ModuleList(convs)
        self.head = nn.Conv2d(c, 1, 1, dtype=torch.float32)
        self.skip = nn.Conv2d(arch.in_channels, 1, 1, dtype=torch.float32)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        h = x
        for conv in self.convs:
            h = torch.relu(conv(h))
        return (self.head(h) + self.skip(x))[:, 0]


def _symmetrised(net: nn.Module, x: torch.Tensor) -> torch.Tensor:
    """``mean_s T_s^{-1} net(T_s x)`` over the 4 quarter turns, each with and without a flip of the columns:
    ``B x C x H x W -> B x H x W``."""
    out = torch.zeros(x.shape[0], *x.shape[-2:], dtype=x.dtype, device=x.device)
    for flip in (False, True):
        xf = torch.flip(x, dims=(-1,)) if flip else x
        for k in range(4):
            y = torch.rot90(net(torch.rot90(xf, k, dims=(-2, -1))), -k, dims=(-2, -1))
            out += torch.flip(y, dims=(-1,)) if flip else y
    return out / 8


# --------------------------------------------------------------------------------------- the guide
class GuideFileError(ValueError):
    """A guide artefact that cannot be loaded (the message names the path and what is wrong), or a corpus
    with no shipped guide (:func:`corpus_guide`)."""


class AmortisedGuide(PyroModule):
    r"""``q(m | z) = prod_k Bernoulli(sigmoid(g(x(z))_k))`` over the latent cells (module docstring).

    Args:
        model: the :class:`~ogm_ppl.OccupancyModel` whose site ``"m"`` the guide samples when called as a
            Pyro guide (optional: every method also takes a model).
        channels, dilations, phase, delta: the :class:`GuideArchitecture`.
        name: Pyro name prefix of the weights (default ``"AmortisedGuide_<n>"``, unique in the process).
        seed: seeds the weights' initialisation (the global torch generator is left as it was).

    As a Pyro guide (``forward``) it takes the model's arguments (``readings``) or, under
    ``pyro.infer.CSIS``, ``observations={"z": readings}``, and samples site ``"m"``: float 0/1 latent cells,
    event shape ``L`` as the model's. Its weights are Pyro parameters ``"<name>.net.*"``.
    """

    def __init__(
        self,
        model: OccupancyModel | None = None,
        *,
        channels: int = 16,
        dilations: tuple[int, ...] = (1, 2, 4, 1),
        phase: tuple[int, int] = (3, 3),
        delta: str = "p21",
        name: str | None = None,
        seed: int = 0,
    ) -> None:
        super().__init__(guide_name(self, name))
        self.occupancy = model
        ph = tuple(phase)
        if len(ph) != 2:
            raise ValueError(f"bad guide architecture: phase must be (h, w), got {phase!r}")
        self.arch = GuideArchitecture(channels, tuple(dilations), (ph[0], ph[1]), delta)
        with torch.random.fork_rng(devices=[]):
            torch.manual_seed(int(seed))
            net = GuideNet(self.arch)
        to_pyro_module_(net)
        self.net = net
        self._cache: tuple | None = None
        self._checked: OccupancyModel | None = None
        self.trained_for: dict = {}
        self._symmetrize = False

    @property
    def symmetrize(self) -> bool:
        r"""Average the logits over the 8 symmetries of the square (test-time symmetrisation, 8 network passes):
        with :math:`T_s` the ``s``-th turn or flip of the grid,
        :math:`\bar g(x) = \tfrac18 \sum_s T_s^{-1} g(T_s x)`, which commutes with every turn and flip of the
        scene (the guide's training turns its windows at random, so each term estimates the same logits).
        Only for a guide without tile-phase channels (``phase == (0, 0)``), whose features turn with the grid.
        Default ``False``."""
        return self._symmetrize

    @symmetrize.setter
    def symmetrize(self, on: bool) -> None:
        if not isinstance(on, bool):
            raise TypeError(f"symmetrize must be True or False, got {on!r}")
        if on and self.arch.phase != (0, 0):
            raise ValueError(
                f"a guide with tile-phase channels (phase {self.arch.phase}) cannot be symmetrised: the tiling "
                "does not turn with the grid"
            )
        self._symmetrize = on

    @property
    def name(self) -> str:
        return self._pyro_name

    # ------------------------------------------------------------------ evaluation
    def _model(self, model: OccupancyModel | None) -> OccupancyModel:
        model = self.occupancy if model is None else model
        if model is None:
            raise ValueError("this guide has no model: pass one (AmortisedGuide(model) or method(model))")
        return model

    def features(self, model: OccupancyModel | None = None, readings: torch.Tensor | None = None) -> torch.Tensor:
        """:func:`evidence_features` with this guide's delta and phase (the model's own readings cached)."""
        model = self._model(model)
        if readings is None:
            if self._cache is not None and self._cache[0] is model:
                return self._cache[1]
            x = evidence_features(model, None, self.arch.delta, self.arch.phase)
            self._cache = (model, x)
            return x
        return evidence_features(model, readings, self.arch.delta, self.arch.phase)

    def cell_logits(self, model: OccupancyModel | None = None, readings: torch.Tensor | None = None) -> torch.Tensor:
        """Logits of every cell, ``K`` float64 (``... x K`` for a batch of readings); differentiable in
        the weights. Pinned cells hold their (unused) network output."""
        model = self._model(model)
        if self._checked is not model:
            self.check_setting(model)
        x = self.features(model, readings)
        batch = x.shape[:-3]
        x = x.reshape(-1, *x.shape[-3:])
        out = _symmetrised(self.net, x) if self._symmetrize else self.net(x)
        return out.reshape(*batch, model.num_cells).to(torch.float64)

    def check_setting(self, model: OccupancyModel, *, noise_known: bool = True) -> bool:
        """Whether ``model``'s sensor lies inside the setting the guide was trained for, as its
        ``trained_for["scans"]`` records it (a corpus guide's ``range_cells`` and ``sigma_cells``); warns
        (:class:`~ogm_ppl.inference.variational.FittedSettingWarning`) if not. The rules of the update terms'
        check: the rays' median maximum range in cells within a factor :data:`F_FACTOR` of ``range_cells``,
        a sensor's scalar ``sigma`` (cells) within :data:`SIGMA_TOLERANCE` of ``sigma_cells``
        (``noise_known=False``: the range alone). Only what both record is compared: a guide without that
        record passes. :meth:`cell_logits` checks each model once."""
        from ogm_ppl.models.delta_setting import FittedSettingWarning, setting_mismatches

        self._checked = model
        scans = self.trained_for.get("scans")
        if not isinstance(scans, dict):
            return True
        F_fit, sigma_fit = _positive(scans.get("range_cells")), _positive(scans.get("sigma_cells"))
        F = float(np.median(model.rays.max_range_cells())) if F_fit is not None and model.rays.num_rays else None
        sigma = getattr(model.sensor, "sigma", None)
        known = noise_known and sigma_fit is not None and sigma is not None and torch.as_tensor(sigma).numel() == 1
        s = float(torch.as_tensor(sigma)) if known else None
        fit, used, flags = [], [], []
        if F is not None:
            fit.append(f"F = {F_fit:g} cells")
            used.append(f"F = {F:g} cells")
            flags.append(f"--range-cells {F:g}")
        if s is not None:
            fit.append(f"sigma = {sigma_fit:g} cells")
            used.append(f"sigma = {s:g} cells")
            flags.append(f"--sigma {s:g}")
        bad = setting_mismatches(sigma_fit, F_fit, s, F)
        if not bad:
            return True
        corpus = self.trained_for.get("corpus")
        name = f"the guide learned on corpus {corpus!r}" if isinstance(corpus, str) else "this guide"
        if corpus == "files":
            name = "the guide learned on plan files"
        several = self.trained_for.get("corpora")  # a guide of several corpora records each one's plans
        sources = list(several) if isinstance(several, dict) else corpus.split("+") if isinstance(corpus, str) else []
        corpora = [c for c in sources if c != "files"]  # "files": plan files of one's own
        maps = (["--corpus", *corpora] if corpora else []) + (["--plan-files", "PLANS"] if "files" in sources else [])
        warnings.warn(
            FittedSettingWarning(
                f"{name} was trained for {', '.join(fit)} but is used at {', '.join(used)} ({'; '.join(bad)}); "
                f"outside its setting its marginals can be far off. Train one for this sensor: ogm-ppl train-guide "
                f"{' '.join(maps or ['--corpus', 'C'])} {' '.join(flags)} --out FILE.npz "
                "(ogm_ppl.learn.train_corpus_guide)"
            ),
            stacklevel=2,
        )
        return False

    def latent_logits(self, model: OccupancyModel | None = None, readings: torch.Tensor | None = None) -> torch.Tensor:
        """Logits of the latent cells, ``L`` (``... x L``), in ``model.latent`` order."""
        model = self._model(model)
        return self.cell_logits(model, readings)[..., model.latent]

    def distribution(self, model: OccupancyModel | None = None, readings: torch.Tensor | None = None):
        """``q(m | z)`` as a Pyro distribution over the latent cells (event shape ``L``)."""
        return dist.Bernoulli(logits=self.latent_logits(model, readings)).to_event(1)

    def forward(self, readings=OBSERVED, observations: dict | None = None):
        """Sample site ``"m"`` from ``q(m | z)``; ``z`` = ``observations["z"]`` (CSIS), else ``readings``
        (the model's own readings by default, as :meth:`OccupancyModel.model`)."""
        model = self._model(None)
        if observations is not None and "z" in observations:
            readings = observations["z"]
        if readings is None:
            raise ValueError(
                "the amortised guide conditions on readings; got readings=None (the model "
                "simulates them then: there is nothing to amortise over)"
            )
        z = None if isinstance(readings, str) and readings == OBSERVED else readings
        return pyro.sample("m", self.distribution(model, z))

    @torch.no_grad()
    def marginals(self, model: OccupancyModel | None = None, readings: torch.Tensor | None = None) -> torch.Tensor:
        """One-pass map estimate: ``q(m_k = 1 | z)`` for all ``K`` cells (pinned cells 0), float64."""
        model = self._model(model)
        p = torch.sigmoid(self.cell_logits(model, readings))
        return torch.where(model.known_free, 0.0, p)

    @torch.no_grad()
    def sample_maps(
        self, model: OccupancyModel | None = None, n: int = 1, generator: torch.Generator | None = None
    ) -> torch.Tensor:
        """``n`` maps drawn from ``q(m | z)``: ``n x K`` float64 0/1, pinned cells 0."""
        p = self.marginals(model)
        u = torch.rand((int(n), p.numel()), generator=generator, dtype=torch.float64)
        return (u < p).to(torch.float64)

    def log_prob(
        self, maps: torch.Tensor, model: OccupancyModel | None = None, readings: torch.Tensor | None = None
    ) -> torch.Tensor:
        """``log q(m | z)`` of maps ``... x K`` (or latent values ``... x L``) -> ``...`` (pinned cells are
        not scored)."""
        model = self._model(model)
        maps = torch.as_tensor(maps, dtype=torch.float64)
        if maps.shape[-1] == model.num_cells and maps.shape[-1] != len(model.latent):
            maps = maps[..., model.latent]
        return self.distribution(model, readings).log_prob(maps)

    def csis_loss(self, model: OccupancyModel, maps: torch.Tensor, readings: torch.Tensor) -> torch.Tensor:
        r"""The inference-compilation loss on a batch of joint draws ``(m_b, z_b) ~ p(m) p(z | m)`` of one
        model's rays: ``(1/B) sum_b -log q(m_b | z_b)`` (nats per map, differentiable)."""
        maps = torch.as_tensor(maps, dtype=torch.float64)
        logits = self.latent_logits(model, readings)
        target = maps[..., model.latent] if maps.shape[-1] == model.num_cells else maps
        nll = torch.nn.functional.binary_cross_entropy_with_logits(logits, target, reduction="none").sum(-1)
        return nll.mean()

    # ------------------------------------------------------------------ artefacts
    def save(self, path: str | os.PathLike, meta: dict | None = None) -> Path:
        """Write the weights and architecture to ``path`` (``.npz``, no pickle); ``meta`` (JSON-able:
        the prior and sensor it was trained for, ...) is stored as text. Atomic."""
        path = Path(path)
        if path.suffix != ".npz":
            raise ValueError(f"{path}: a guide artefact is an .npz file")
        a = self.arch
        payload = {
            "kind": np.array(_KIND),
            "format": np.array(FORMAT, dtype=np.int64),
            "feature_version": np.array(FEATURE_VERSION, dtype=np.int64),
            "channels": np.array(a.channels, dtype=np.int64),
            "dilations": np.array(a.dilations, dtype=np.int64),
            "phase": np.array(a.phase, dtype=np.int64),
            "delta": np.array(a.delta),
            "meta": np.array(json.dumps(meta if meta is not None else self.trained_for, sort_keys=True)),
        }
        for k, v in self.net.state_dict().items():
            payload[f"param/{k}"] = v.detach().cpu().to(torch.float32).numpy()
        with atomic_write(path) as f:
            np.savez_compressed(f, **payload)  # type: ignore[arg-type]  # numpy stub: **arrays could fill allow_pickle
        return path

    @classmethod
    def load(
        cls, path: str | os.PathLike, model: OccupancyModel | None = None, name: str | None = None
    ) -> AmortisedGuide:
        """A guide rebuilt from an artefact written by :meth:`save` (validated; :class:`GuideFileError`
        names the path and the problem)."""
        arch, state, meta = _read_artefact(Path(path))
        guide = cls(
            model, channels=arch.channels, dilations=arch.dilations, phase=arch.phase, delta=arch.delta, name=name
        )
        guide._set_weights(state)
        guide.trained_for = meta
        return guide

    def load_weights(self, path: str | os.PathLike) -> None:
        """Load an artefact's weights into this guide; refused (:class:`GuideFileError`) when its
        architecture differs from this guide's, naming the field."""
        path = Path(path)
        arch, state, meta = _read_artefact(path)
        if arch != self.arch:
            diff = [
                f"{k}: file {v!r}, guide {getattr(self.arch, k)!r}"
                for k, v in asdict(arch).items()
                if v != getattr(self.arch, k)
            ]
            raise GuideFileError(f"{path}: a guide of another architecture ({'; '.join(diff)})")
        self._set_weights(state)
        self.trained_for = meta
        self._checked = None

    def _set_weights(self, state: dict[str, torch.Tensor]) -> None:
        with torch.no_grad():
            for k, v in self.net.state_dict().items():
                v.copy_(state[k])  # in place: the Pyro param store keeps pointing at the same tensors
        self._cache = None


def _positive(v) -> float | None:
    """A recorded positive number as a float, else ``None``."""
    ok = isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) and v > 0
    return float(v) if ok else None


def _read_artefact(path: Path) -> tuple[GuideArchitecture, dict[str, torch.Tensor], dict]:
    what = "a guide written by AmortisedGuide.save (ogm_ppl.learn.train_prior_guide, ogm-ppl train-guide)"
    hint = f"expected {what}"
    arrays = read_npz(path, what, GuideFileError)
    fields = ("kind", "format", "feature_version", "channels", "dilations", "phase", "delta", "meta")
    missing = [k for k in fields if k not in arrays]
    if missing:
        raise GuideFileError(f"{path}: missing {', '.join(missing)}; {hint}")

    def text(key: str) -> str:
        a = arrays[key]
        if a.dtype.kind != "U" or a.ndim != 0:
            raise GuideFileError(f"{path}: field {key!r} must be a text scalar, got {a.dtype} of shape {a.shape}")
        return str(a)

    def ints(key: str, ndim: int) -> np.ndarray:
        a = arrays[key]
        if a.dtype.kind not in "iu" or a.ndim != ndim:
            raise GuideFileError(
                f"{path}: field {key!r} must be an integer array of {ndim} dimensions, got {a.dtype} of shape {a.shape}"
            )
        return a

    if text("kind") != _KIND:
        raise GuideFileError(f"{path}: kind {text('kind')!r}, not {_KIND!r}; {hint}")
    if int(ints("format", 0)) != FORMAT:
        raise GuideFileError(f"{path}: artefact format {int(arrays['format'])}, this version reads {FORMAT}")
    if int(ints("feature_version", 0)) != FEATURE_VERSION:
        raise GuideFileError(
            f"{path}: feature set version {int(arrays['feature_version'])}, this version "
            f"computes {FEATURE_VERSION}: the weights would read other inputs"
        )
    channels = int(ints("channels", 0))
    dilations = tuple(int(d) for d in ints("dilations", 1))
    ph = ints("phase", 1)
    if ph.shape != (2,):
        raise GuideFileError(f"{path}: field 'phase' must hold 2 integers, got {ph.shape[0]}")
    phase = (int(ph[0]), int(ph[1]))
    delta = text("delta")
    problems = _architecture_problems(channels, dilations, phase, delta)
    if problems:
        raise GuideFileError(f"{path}: {problems}")
    arch = GuideArchitecture(channels, dilations, phase, delta)
    try:
        meta = json.loads(text("meta"))
    except json.JSONDecodeError as e:
        raise GuideFileError(f"{path}: field 'meta' is not JSON ({e.msg})") from None
    if not isinstance(meta, dict):
        raise GuideFileError(f"{path}: field 'meta' must be a JSON object")
    expected = {k: tuple(v.shape) for k, v in GuideNet(arch).state_dict().items()}
    got = {k[len("param/") :]: a for k, a in arrays.items() if k.startswith("param/")}
    extra = sorted(set(arrays) - set(fields) - {f"param/{k}" for k in expected})
    if extra:
        raise GuideFileError(f"{path}: unexpected entries {extra} for this architecture")
    absent = sorted(set(expected) - set(got))
    if absent:
        raise GuideFileError(f"{path}: weights {absent} missing for this architecture")
    state = {}
    for k, shape in expected.items():
        a = got[k]
        if a.dtype != np.float32:
            raise GuideFileError(f"{path}: weight {k!r} must be float32, got {a.dtype}")
        if tuple(a.shape) != shape:
            raise GuideFileError(f"{path}: weight {k!r} has shape {tuple(a.shape)}, the architecture needs {shape}")
        if not np.isfinite(a).all():
            raise GuideFileError(f"{path}: weight {k!r} holds a non-finite value")
        state[k] = torch.from_numpy(a.copy())
    return arch, state, meta


def shipped_guide(model: OccupancyModel | None = None) -> AmortisedGuide:
    """The trained guide shipped in ``ogm_ppl/fitted/guide_amortised.npz`` (trained for the prior and
    sensor in its ``trained_for``; see the JSON sidecar)."""
    return AmortisedGuide.load(SHIPPED_GUIDE, model)


def corpus_guide_path(corpus: str) -> Path:
    """Where the guide learned on ``corpus``'s training plans ships: ``ogm_ppl/fitted/guide_<corpus>.npz``."""
    return SHIPPED_GUIDE.parent / f"guide_{corpus}.npz"


def corpus_guides() -> list[str]:
    """The corpora with a shipped corpus guide (:func:`corpus_guide`)."""
    return sorted(p.stem.removeprefix("guide_") for p in SHIPPED_GUIDE.parent.glob("guide_*.npz") if p != SHIPPED_GUIDE)


def unknown_corpus_message(corpus: str) -> str:
    """Why ``corpus`` names no shipped corpus guide: the corpora that have one (names are case-sensitive: a
    hint when the lower-case name is one) and how to train one. :func:`corpus_guide`, ``init="guide:CORPUS"``
    and the methods' options say it alike.

    >>> unknown_corpus_message("HouseExpo")  # doctest: +ELLIPSIS
    "no guide learned on corpus 'HouseExpo' (did you mean 'houseexpo'?); shipped: ..., houseexpo, ..."
    """
    shipped = corpus_guides()
    low = corpus.lower() if isinstance(corpus, str) else None
    hint = f" (did you mean {low!r}?)" if low != corpus and low in shipped else ""
    return (
        f"no guide learned on corpus {corpus!r}{hint}; shipped: {', '.join(shipped)} "
        "(ogm-ppl train-guide --corpus C --out FILE.npz trains one: ogm_ppl.learn.train_corpus_guide)"
    )


def corpus_guide(corpus: str, model: OccupancyModel | None = None) -> AmortisedGuide:
    r"""The guide trained on the training plans of a floor-plan corpus (:func:`ogm_ppl.learn.train_corpus_guide`,
    ``ogm-ppl train-guide --corpus C``):
    windows of the plans the corpus's prior tables were learned from, scanned by the stop-and-scan simulator,
    so that ``q(m_k = 1 | z)`` approximates the posterior marginal with the corpus itself as the prior,

    .. math:: q_\phi(m_k = 1 \mid z) \approx p_\text{corpus}(m_k = 1 \mid z)
        = \sum_m m_k\, p_\text{corpus}(m)\, p(z \mid m) / p_\text{corpus}(z),

    with a receptive field of ``1 + 2 * sum(dilations)`` cells (Chapter 5's question, what a map predicts of the
    cells no ray reached, answered by a network instead of a table). Its ``trained_for`` names the corpus, the
    SHA-256 of its training plans' names and the sensor it was trained for (3 stops x 90 beams, 75-cell range
    by default); evaluate it on held-out plans only, with that sensor (:meth:`AmortisedGuide.check_setting` warns
    otherwise). Unknown corpus: :class:`GuideFileError` (:func:`unknown_corpus_message`).
    """
    if corpus not in corpus_guides():
        raise GuideFileError(unknown_corpus_message(corpus))
    return AmortisedGuide.load(corpus_guide_path(corpus), model)


# --------------------------------------------------------------------------------------- use (b)
def guide_initial_map(
    guide: AmortisedGuide, model: OccupancyModel, how: str = "mode", generator: torch.Generator | None = None
) -> torch.Tensor:
    """A starting map for Gibbs (``K`` float 0/1, pinned cells free) from the guide: ``"mode"`` (the
    mean-field mode, ``q_k > 1/2``) or ``"sample"`` (a draw from ``q(m | z)``). Pass it as ``init=`` to
    :class:`~ogm_ppl.inference.mcmc.gibbs.CellGibbs` / ``PatchGibbs``."""
    if how == "mode":
        m = (guide.marginals(model) > 0.5).to(torch.float64)
    elif how == "sample":
        m = guide.sample_maps(model, 1, generator)[0]
    else:
        raise ValueError(f"how must be 'mode' or 'sample', got {how!r}")
    m[model.known_free] = 0.0
    return m


def _bits_per_cell(nats_per_map: float, cells: int) -> float:
    return nats_per_map / max(cells, 1) / math.log(2.0)


# --------------------------------------------------------------------------------------- simulated scenes
@dataclass(frozen=True, eq=False)
class Scene:
    """Poses and beams of a simulated 2D stop-and-scan dataset (grid resolution 1, so ranges are in cells):
    the rays of the model whose joint ``p(m) p(z | m)`` inference compilation draws from.

    :meth:`model` builds the :class:`~ogm_ppl.OccupancyModel` of given readings (default: placeholders,
    all max range, for drawing ``(m, z)`` from its joint with ``prior.sample_given_free(model.known_free)``
    and :meth:`OccupancyModel.simulate_readings`).
    """

    grid: Grid
    poses: np.ndarray
    angles: np.ndarray
    max_range_cells: float
    sensor: SensorModel
    prior: MapPrior

    def model(self, readings: torch.Tensor | None = None) -> OccupancyModel:
        """The model of these poses with ``readings`` (``R = poses x beams`` values of site ``"z"``, scan by
        scan). Ranges below 0 (Gaussian noise near the sensor) are read as 0, the nearest range a
        :class:`~ogm_ppl.Scans` holds; both fall in the sensor's cell (kappa 0), so the guide's features
        are the same."""
        from ogm_ppl import Scans, raycast

        P, B = len(self.poses), len(self.angles)
        F = float(self.max_range_cells)
        if readings is None:
            ranges = np.full((P, B), F)
        else:
            z = torch.as_tensor(readings, dtype=torch.float64)
            if z.shape != (P * B,) or torch.isnan(z).any():
                raise ValueError(f"readings must be {P * B} numbers (poses x beams)")
            ranges = z.numpy().clip(0.0, F).reshape(P, B)
        scans = Scans(self.poses, self.angles, ranges, F)
        model = OccupancyModel(self.grid, raycast(self.grid, scans), self.sensor, self.prior)
        if model.rays.num_rays != P * B:
            raise RuntimeError("a beam got no ray")
        return model


def random_scene(
    prior: MapPrior,
    shape: tuple[int, int],
    num_poses: int,
    beams: int = 120,
    max_range_cells: float = 12.0,
    sensor: SensorModel | None = None,
    rng: np.random.Generator | None = None,
    free: np.ndarray | None = None,
) -> Scene:
    """``num_poses`` 360 degree scans (``beams`` each, range ``max_range_cells``) from poses drawn uniformly
    over the grid (over the ``free`` cells of a ``rows x cols`` mask when given), yaw 0, resolution 1.
    ``sensor`` defaults to ``GaussianRange(1.0)``."""
    from ogm_ppl import GaussianRange

    rng = np.random.default_rng() if rng is None else rng
    grid = Grid(tuple(int(s) for s in shape), resolution=1.0)
    if free is None:
        cells = np.stack([rng.integers(0, grid.rows, num_poses), rng.integers(0, grid.cols, num_poses)], 1)
    else:
        ok = np.flatnonzero(np.asarray(free, bool).ravel())
        if not len(ok):
            raise ValueError("no free cell to place a pose in")
        cells = np.stack(np.divmod(rng.choice(ok, num_poses), grid.cols), 1)
    xy = grid.cell_to_world(cells) + rng.uniform(-0.3, 0.3, (num_poses, 2))
    poses = np.c_[xy, np.zeros(num_poses)]
    angles = np.arange(beams) * (2 * np.pi / beams)
    return Scene(
        grid, poses, angles, float(max_range_cells), sensor if sensor is not None else GaussianRange(1.0), prior
    )
