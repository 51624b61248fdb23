r"""The amortised guide ``q(m | z)`` over 2D maps, compiled from the model (inference compilation, Le, Baydin
and Wood 2017; Pyro's ``CSIS``): its marginals, logits (symmetrised on request), the CSIS loss, the record
of the setting it was trained for with the warning for a sensor outside it, and saving and loading.

.. math::
    q_\phi(m \mid z) = \prod_{k \in \text{latent}} \mathrm{Bernoulli}\bigl(m_k;\
        \sigma(g_\phi(x(z))_k)\bigr),

with ``x(z)`` the features of :mod:`~ogm_ppl.inference.variational.amortised_features` and ``g_phi`` the
network of :mod:`~ogm_ppl.inference.variational.amortised_net`. Trained on the model's own joint
``(m, z) ~ p(m) p(z | m)``, the loss is

.. math::
    \mathcal{L}(\phi) = \mathbb{E}_{p(m, z)}\bigl[-\log q_\phi(m \mid z)\bigr]
        = \mathbb{E}_{p(z)}\bigl[\mathrm{KL}(p(m \mid z) \,\|\, q_\phi(m \mid z))\bigr] + \text{const}

(:meth:`AmortisedGuide.csis_loss`, the batch estimate), whose minimiser at each ``z`` is the posterior's
marginals. :func:`guide_initial_map` starts Gibbs near the posterior from the guide.
"""

from __future__ import annotations

import math
import os
import warnings
from dataclasses import asdict
from pathlib import Path

import numpy as np
import pyro
import pyro.distributions as dist
import torch
from pyro.nn import PyroModule
from pyro.nn.module import to_pyro_module_

from ogm_ppl.inference.variational.amortised_fast import fast_logits
from ogm_ppl.inference.variational.amortised_features import evidence_features
from ogm_ppl.inference.variational.amortised_files import GuideFileError, read_guide_file, write_guide_file
from ogm_ppl.inference.variational.amortised_net import GuideArchitecture, GuideNet, _symmetrised
from ogm_ppl.inference.variational.guides import guide_name
from ogm_ppl.models.occupancy import OBSERVED, OccupancyModel

__all__ = ["AmortisedGuide", "guide_initial_map"]


class AmortisedGuide(PyroModule):
    r"""``q(m | z) = prod_k Bernoulli(sigmoid(g(x(z))_k))`` over the latent cells (module docstring).

    Args:
        model: the :class:`~ogm_ppl.OccupancyModel` whose site ``"m"`` the guide samples when called as a
            Pyro guide (optional: every method also takes a model).
        channels, dilations, phase, delta: the :class:`~ogm_ppl.inference.variational.amortised_net.GuideArchitecture`.
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
        """:func:`~ogm_ppl.inference.variational.amortised_features.evidence_features` with this guide's delta and phase
        (the model's own readings cached)."""
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
        the weights. Pinned cells hold their (unused) network output. With gradients off (``torch.no_grad``,
        as :meth:`marginals`) the map comes from
        :func:`~ogm_ppl.inference.variational.amortised_fast.fast_logits`: the same sums in another order
        (equal to float32 rounding), several times faster."""
        model = self._model(model)
        if self._checked is not model:
            self.check_setting(model)
        x = self.features(model, readings)
        batch = x.shape[:-3]
        x = x.reshape(-1, *x.shape[-3:])
        if not torch.is_grad_enabled():
            out = fast_logits(self.net, x, self._symmetrize)
        else:
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
        return write_guide_file(
            Path(path), self.arch, self.net.state_dict(), meta if meta is not None else self.trained_for
        )

    @classmethod
    def load(
        cls, path: str | os.PathLike, model: OccupancyModel | None = None, name: str | None = None
    ) -> AmortisedGuide:
        """A guide rebuilt from an artefact written by :meth:`save` (validated;
        :class:`~ogm_ppl.inference.variational.amortised_files.GuideFileError` names the path and the problem)."""
        arch, state, meta = read_guide_file(Path(path))
        guide = cls(
            model, channels=arch.channels, dilations=arch.dilations, phase=arch.phase, delta=arch.delta, name=name
        )
        guide._set_weights(state)
        guide.trained_for = meta
        return guide

    def load_weights(self, path: str | os.PathLike) -> None:
        """Load an artefact's weights into this guide; refused
        (:class:`~ogm_ppl.inference.variational.amortised_files.GuideFileError`) when its architecture differs from this
        guide's, naming the field."""
        path = Path(path)
        arch, state, meta = read_guide_file(path)
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
