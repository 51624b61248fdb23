r"""Tempered posteriors and parallel tempering over whole maps (for Chapter 4's samplers under the strongly
coupled learned priors of Chapter 5).

**Tempered targets.** For exponents ``beta_p, beta_l >= 0``

.. math:: \pi_\beta(m) \propto \tilde p(m)^{\beta_p}\, L(m)^{\beta_l}, \qquad
          L(m) = \prod_n p(z_n \mid f_n(m)),

the posterior at ``beta_p = beta_l = 1``. :func:`tempered_model` builds an
:class:`~ogm_ppl.OccupancyModel` whose prior is :class:`~ogm_ppl.priors.TemperedPrior` (its compiled face is
the bundle's ``tempered(beta_p)``: every log-potential times ``beta_p``) and whose likelihood table is ``beta_l`` times
the model's (the table ``ll[r, f] = log p(z_r | f)`` is the only place the readings enter the compiled
kernels, through :meth:`~ogm_ppl.OccupancyModel.ray_index`), so every kernel of
:mod:`~ogm_ppl.inference.mcmc.gibbs` samples ``pi_beta`` exactly, unchanged. ``-inf`` entries (a map the
prior forbids, a reading a first hit makes impossible) stay ``-inf`` at every ``beta``, so ``beta = 0``
means the factor reduced to its support: ``beta_p = 0`` is the uniform distribution over the prior's
support, ``beta_l = 0`` the prior restricted to maps under which no reading is impossible (the limits
``beta -> 0+``). The cells beyond the grid edge stay marginalised under the model's ``lambda_out``: the
tempered likelihood is ``L^beta_l`` of the model's ``L``.

**Parallel tempering** (Swendsen & Wang 1986; Geyer 1991). :class:`ParallelTempering` runs one chain per
rung of a ladder ``1 = beta_0 > beta_1 > ... > beta_{n-1} > 0`` on the product target
``prod_i pi_{beta_i}``. A sweep is one sweep of every rung's kernel, then swap moves between adjacent rungs
``i, j = i + 1``: exchange their maps ``x_i, x_j`` with probability

.. math:: \min\Big(1, \frac{\pi_{\beta_i}(x_j)\,\pi_{\beta_j}(x_i)}{\pi_{\beta_i}(x_i)\,\pi_{\beta_j}(x_j)}\Big)
          = \min\big(1, \exp[(\beta^p_i - \beta^p_j)(\log\tilde p(x_j) - \log\tilde p(x_i))
          + (\beta^l_i - \beta^l_j)(\log L(x_j) - \log L(x_i))]\big)

(whole-map unnormalised log-densities; the normalisers cancel). Each move is a Metropolis-Hastings move on
the product target, so every schedule of them leaves it invariant and the cold chain (``beta = 1``) samples
the posterior: it is what :meth:`~ParallelTempering.current_params`, the samples and the checkpoint's ``m``
report. A hot chain mixes across the modes the coupled prior freezes the cold one into, and swaps carry
its moves down the ladder. :func:`geometric_ladder` gives ``beta_i = beta_min^{i / (n - 1)}``.
"""

from __future__ import annotations

import copy
import itertools
import math
from collections.abc import Mapping, Sequence

import numpy as np
import torch

from ogm_ppl.inference.mcmc.gibbs import CellGibbs, PatchGibbs
from ogm_ppl.inference.mcmc.kernel import KernelStateError, MapKernel
from ogm_ppl.models.occupancy import OccupancyModel
from ogm_ppl.priors.tempered import TemperedPrior, _check_exponent, _scale_log

__all__ = ["ParallelTempering", "check_ladder", "geometric_ladder", "tempered_model"]

TEMPERS = ("prior", "likelihood", "both")
SWAPS = ("even-odd", "all", "random")
KERNELS = ("cell", "patch")


def tempered_model(model: OccupancyModel, beta_prior: float = 1.0, beta_lik: float = 1.0) -> OccupancyModel:
    r"""The model of ``pi_beta(m) ∝ p~(m)^beta_prior L(m)^beta_lik`` (module docstring): a shallow copy of
    ``model`` with prior :class:`~ogm_ppl.priors.TemperedPrior` and likelihood table ``beta_lik * model.loglik_table``
    (``-inf`` kept). ``beta_prior = beta_lik = 1`` returns ``model`` itself. Its ``log_joint`` is
    ``beta_prior log p~(m) + beta_lik log L(m)``; any kernel built on it samples ``pi_beta`` exactly."""
    bp = _check_exponent(beta_prior, "beta_prior")
    bl = _check_exponent(beta_lik, "beta_lik")
    if bp == 1.0 and bl == 1.0:
        return model
    out = copy.copy(model)
    if bp != 1.0:
        out.prior = TemperedPrior(model.prior, bp)
    if bl != 1.0:
        out.loglik_table = _scale_log(model.loglik_table, bl)
    return out  # its ray index is its own table's: OccupancyModel.ray_index keeps one per table


def geometric_ladder(num_rungs: int, beta_min: float) -> tuple[float, ...]:
    """``beta_i = beta_min^{i / (n - 1)}``, ``i = 0..n-1``: from 1 down to ``beta_min`` in ``(0, 1)``,
    equal ratios between neighbours (constant swap rates when the log-density's variance scales as
    ``1 / beta^2``, as for a large field). ``num_rungs = 1`` gives ``(1.0,)``."""
    n = int(num_rungs)
    if n < 1:
        raise ValueError(f"num_rungs must be >= 1, got {num_rungs!r}")
    b = float(beta_min)
    if n > 1 and not 0.0 < b < 1.0:
        raise ValueError(f"beta_min must lie in (0, 1), got {beta_min!r}")
    if n == 1:
        return (1.0,)
    return tuple([1.0] + [float(b ** (i / (n - 1))) for i in range(1, n - 1)] + [b])


def check_ladder(betas: Sequence[float]) -> tuple[float, ...]:
    """``betas`` as a tuple, checked: at least one, each in ``(0, 1]``, strictly decreasing from
    ``betas[0] = 1`` (the cold chain)."""
    try:
        b = tuple(float(x) for x in np.asarray(betas, dtype=np.float64).reshape(-1))
    except (TypeError, ValueError):
        raise ValueError(f"betas must be a sequence of numbers, got {betas!r}") from None
    if np.ndim(betas) != 1 or len(b) == 0:
        raise ValueError(f"betas must be a non-empty 1D sequence, got {betas!r}")
    bad = [x for x in b if not (math.isfinite(x) and 0.0 < x <= 1.0)]
    if bad:
        raise ValueError(f"every beta must lie in (0, 1], got {bad[0]!r} in {b}")
    if b[0] != 1.0:
        raise ValueError(f"betas[0] must be 1 (the cold chain samples the posterior), got {b[0]!r}")
    if any(x <= y for x, y in itertools.pairwise(b)):
        raise ValueError(f"betas must be strictly decreasing, got {b}")
    return b


class ParallelTempering(MapKernel):
    r"""Parallel tempering over maps (module docstring): one chain per rung, swaps between neighbours.

    Args:
        model: an :class:`~ogm_ppl.OccupancyModel` (the posterior is the cold rung's target).
        betas: the ladder, strictly decreasing from ``1`` in ``(0, 1]`` (:func:`geometric_ladder`).
        kernel: each rung's sampler: ``"cell"`` (:class:`~ogm_ppl.inference.mcmc.gibbs.CellGibbs`) or
            ``"patch"`` (:class:`~ogm_ppl.inference.mcmc.gibbs.PatchGibbs` of shape ``patch``).
        patch: the patch shape for ``kernel="patch"``.
        temper: which factor rung ``i`` raises to ``beta_i``: ``"prior"`` (``p~^beta L``),
            ``"likelihood"`` (``p~ L^beta``) or ``"both"`` (``(p~ L)^beta``).
        swaps: the swap moves after each sweep: ``"even-odd"`` (pairs ``(0,1), (2,3), ...`` after even
            sweeps, ``(1,2), (3,4), ...`` after odd ones: the non-reversible schedule of Okabe et al. 2001 /
            Syed et al. 2022), ``"all"`` (every adjacent pair, cold end first) or ``"random"`` (one pair
            drawn uniformly).
        scan, update: of every rung's kernel (as in :class:`~ogm_ppl.inference.mcmc.gibbs.CellGibbs`).
        init, delta: the starting map of every rung (:func:`~ogm_ppl.inference.mcmc.kernel.initial_map` of
            ``model``).
        region: as in the rung kernels (the cold chain samples the conditional ``p(m_R' | m_rest, z)``).

    State: :meth:`set_state` (and a ``params["m"]`` that is not the kernel's own, in :meth:`sample`) puts
    one map on every rung; :meth:`set_rung_states` gives each rung its own; :meth:`rung_states` reads them.
    Randomness: the rung kernels' draws and one uniform per swap move, all from torch's generator, so a
    seed fixes the run. :meth:`swap_rates` gives each pair's acceptance rate; :meth:`state_dict` holds every
    rung (``rung{i}.*``, each rung kernel's own entries) and the swap counters, and a kernel built with the
    same arguments that loads it continues the run bit for bit.
    """

    def __init__(
        self,
        model: OccupancyModel,
        betas: Sequence[float],
        kernel: str = "cell",
        patch=(3, 3),
        temper: str = "both",
        swaps: str = "even-odd",
        scan: str = "systematic",
        update: str = "gibbs",
        init="ogm",
        delta="haehnel",
        region=None,
    ) -> None:
        ladder = check_ladder(betas)
        if kernel not in KERNELS:
            raise ValueError(f"kernel must be one of {KERNELS}, got {kernel!r}")
        if temper not in TEMPERS:
            raise ValueError(f"temper must be one of {TEMPERS}, got {temper!r}")
        if swaps not in SWAPS:
            raise ValueError(f"swaps must be one of {SWAPS}, got {swaps!r}")
        super().__init__(model, scan, init, delta, region)
        self.betas = ladder
        self.kernel = kernel
        self.patch = tuple(patch) if isinstance(patch, (tuple, list)) else patch
        self.temper = temper
        self.swaps = swaps
        self.update = update
        self.models = [tempered_model(model, *self.exponents(i)) for i in range(len(ladder))]
        self.rungs: list[MapKernel] = [self._rung_kernel(m) for m in self.models]
        n = max(len(ladder) - 1, 0)
        self._attempts = np.zeros(n, np.int64)
        self._accepts = np.zeros(n, np.int64)
        self._restored = False

    def _rung_kernel(self, model: OccupancyModel) -> MapKernel:
        if self.kernel == "cell":
            return CellGibbs(model, self.scan, self.update, init="free", region=self.region)
        return PatchGibbs(model, self.patch, self.scan, update=self.update, init="free", region=self.region)

    @property
    def num_rungs(self) -> int:
        return len(self.betas)

    def exponents(self, i: int) -> tuple[float, float]:
        """``(beta_prior, beta_lik)`` of rung ``i``."""
        b = self.betas[i]
        return {"prior": (b, 1.0), "likelihood": (1.0, b), "both": (b, b)}[self.temper]

    # --------------------------------------------------------------- set-up and state
    def _set_up(self) -> None:
        super()._set_up()  # the untempered model's ray index (the swaps' log-likelihoods); each rung sets up its own
        self._rows = np.arange(self.model.rays.num_rays)
        self._e = np.asarray([self.exponents(i) for i in range(self.num_rungs)], np.float64)  # n x 2

    def _set_state(self, m) -> None:
        if self._restored:  # load_state_dict has loaded every rung; m is the cold rung's
            self._restored = False
        else:
            for k in self.rungs:
                k.set_state(m)
        self._bind_cold()
        self._terms = np.stack([self._log_terms(i) for i in range(self.num_rungs)])

    def _bind_cold(self) -> None:
        """Make the cold rung's map and first hits this kernel's (a swap hands the cold rung another map)."""
        self.chain.bind(self.rungs[0].state, self.rungs[0].first_hit_state)

    @property
    def state(self) -> np.ndarray:
        """The cold chain's current full map (live ``(K,)`` uint8 array)."""
        if not self.chain.loaded:
            raise RuntimeError(
                "ParallelTempering has no state yet: call setup(), set_state() or load_state_dict() first"
            )
        return self.rungs[0].state

    @property
    def first_hit_state(self) -> np.ndarray:
        return self.rungs[0].first_hit_state

    def rung_states(self) -> np.ndarray:
        """``n x K`` uint8: every rung's current map (a copy; row 0 the cold chain)."""
        return np.stack([k.state.copy() for k in self.rungs])

    def set_rung_states(self, maps) -> None:
        """Make ``maps`` (``n x K`` or ``n x L``, 0/1; row ``i`` for rung ``i``) the rungs' states
        (:meth:`set_state` puts one map on every rung)."""
        self._prepare()
        maps = torch.as_tensor(maps)
        if maps.dim() != 2 or maps.shape[0] != self.num_rungs:
            raise ValueError(f"set_rung_states takes one map per rung ({self.num_rungs}), got {tuple(maps.shape)}")
        for k, m in zip(self.rungs, maps):
            k.set_state(m)
        self._restored = True
        self._set_state(maps[0])

    def sampled_cells(self) -> np.ndarray:
        return self.rungs[0].sampled_cells()

    def _log_terms(self, i: int) -> np.ndarray:
        """``(log p~(x_i), log L(x_i))`` of rung ``i``'s map under the untempered model."""
        x = self.rungs[i].state
        lp = float(self.model.prior.log_prob(torch.from_numpy(x.astype(np.float64))))
        f = np.asarray(self.rungs[i].first_hit_state, dtype=np.int64)
        ll = float(self._ll[self._rows, f].sum())
        return np.array([lp, ll])

    def log_targets(self) -> np.ndarray:
        """``n``: ``log pi_{beta_i}(x_i)`` (unnormalised) of every rung's current map."""
        self._prepare()
        return np.array([self._log_target(i, i) for i in range(self.num_rungs)])

    def _log_target(self, rung: int, of: int) -> float:
        """``beta^p_rung log p~(x_of) + beta^l_rung log L(x_of)`` (``-inf`` where either term is)."""
        t = self._terms[of]
        if not np.isfinite(t).all():
            return -math.inf if (t == -math.inf).any() else math.nan
        return float(self._e[rung] @ t)

    def swap_log_ratio(self, i: int) -> float:
        """The log Metropolis-Hastings ratio of swapping the maps of rungs ``i`` and ``i + 1`` now:
        ``+inf`` when the current pair has no mass and the swapped one has; ``nan`` (never accepted) when
        neither has."""
        self._prepare()
        j = i + 1
        new = self._log_target(i, j) + self._log_target(j, i)
        old = self._log_target(i, i) + self._log_target(j, j)
        if old == -math.inf:
            return math.inf if new > -math.inf else math.nan
        return new - old

    # --------------------------------------------------------------- sampling
    def _pairs(self) -> list[int]:
        n = self.num_rungs - 1
        if n <= 0:
            return []
        if self.swaps == "all":
            return list(range(n))
        if self.swaps == "random":
            return [int(torch.randint(0, n, ()))]
        return list(range(self.sweeps % 2, n, 2))

    def _sweep(self) -> int:
        changes = 0
        for i, k in enumerate(self.rungs):
            before = k.updates
            c = k.step()
            if i == 0:
                changes = c
                self.chain.updates += k.updates - before
            self._terms[i] = self._log_terms(i)
        for i in self._pairs():
            log_r = self.swap_log_ratio(i)
            u = float(torch.rand((), dtype=torch.float64))
            self._attempts[i] += 1
            if log_r == log_r and (log_r >= 0 or math.log(u) < log_r):
                self._accepts[i] += 1
                a, b = self.rungs[i], self.rungs[i + 1]
                xa = a.state.copy()
                a._adopt_map(b.state)
                b._adopt_map(xa)
                self._terms[[i, i + 1]] = self._terms[[i + 1, i]]
                if i == 0:
                    changes += 1
        self._bind_cold()
        return changes

    def swap_rates(self) -> np.ndarray:
        """``n - 1``: the fraction of attempted swaps accepted between rungs ``i`` and ``i + 1`` (NaN:
        none attempted yet)."""
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(self._attempts > 0, self._accepts / np.maximum(self._attempts, 1), np.nan)

    @property
    def swap_attempts(self) -> np.ndarray:
        return self._attempts.copy()

    @property
    def swap_accepts(self) -> np.ndarray:
        return self._accepts.copy()

    def logging(self):
        out = super().logging()
        rates = self.swap_rates()
        if len(rates):
            out["swap rate"] = " ".join("-" if r != r else f"{r:.2f}" for r in rates)
        return out

    def diagnostics(self):
        out = super().diagnostics()
        out["swap rates"] = self.swap_rates().tolist()
        return out

    # --------------------------------------------------------------- checkpoints
    def _extra_state(self) -> dict[str, np.ndarray]:
        d: dict[str, np.ndarray] = {
            "betas": np.asarray(self.betas, np.float64),
            "swap_attempts": self._attempts.copy(),
            "swap_accepts": self._accepts.copy(),
        }
        for i, k in enumerate(self.rungs):
            for key, v in k.state_dict().items():
                d[f"rung{i}.{key}"] = v
        return d

    def _load_extra_state(self, state: Mapping) -> None:
        n = self.num_rungs
        for key in ("betas", "swap_attempts", "swap_accepts"):
            if key not in state:
                raise KernelStateError(f"ParallelTempering state lacks {key}")
        betas = np.asarray(state["betas"])
        if betas.shape != (n,) or betas.dtype.kind != "f" or not np.array_equal(betas, np.asarray(self.betas)):
            raise KernelStateError(f"ParallelTempering state 'betas' {betas.tolist()} differ from {list(self.betas)}")
        counts = {}
        for key in ("swap_attempts", "swap_accepts"):
            v = np.asarray(state[key])
            if v.shape != (n - 1,) or v.dtype.kind not in "iu" or (v < 0).any():
                raise KernelStateError(f"ParallelTempering state {key!r} must be {n - 1} non-negative integers")
            counts[key] = v.astype(np.int64)
        if (counts["swap_accepts"] > counts["swap_attempts"]).any():
            raise KernelStateError("ParallelTempering state has more accepted swaps than attempted ones")
        extra = [k for k in state if k.startswith("rung") and int(k[4:].split(".")[0]) >= n]
        if extra:
            raise KernelStateError(f"ParallelTempering state holds rungs beyond the {n} of this ladder: {extra[0]}")
        subs = []
        for i in range(n):
            prefix = f"rung{i}."
            sub = {k[len(prefix) :]: v for k, v in state.items() if k.startswith(prefix)}
            if not sub:
                raise KernelStateError(f"ParallelTempering state lacks rung {i}")
            subs.append(sub)
        if not np.array_equal(np.asarray(subs[0].get("m")), np.asarray(state["m"])):
            raise KernelStateError("ParallelTempering state 'm' is not the cold rung's map (rung0.m)")
        for i, (k, sub) in enumerate(zip(self.rungs, subs)):
            try:
                k.load_state_dict(sub)
            except KernelStateError as e:
                raise KernelStateError(f"ParallelTempering rung {i}: {e}") from None
        self._attempts, self._accepts = counts["swap_attempts"], counts["swap_accepts"]
        self._restored = True

    def settings(self) -> dict:
        out = super().settings()
        out.pop("rungs", None)
        out.pop("models", None)
        out["betas"] = tuple(self.betas)
        return out

    def __repr__(self) -> str:
        return (
            f"ParallelTempering({self.kernel}, betas={tuple(round(b, 4) for b in self.betas)}, "
            f"temper={self.temper!r}, swaps={self.swaps!r})"
        )
