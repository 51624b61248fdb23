r"""A cycle of map kernels: one sweep is a sweep of each kernel in turn (Chapter 4).

If every kernel ``P_1, ..., P_n`` leaves the posterior ``pi = p(m | z)`` invariant, so does their
composition ``P = P_1 P_2 ... P_n`` (Tierney 1994, "cycles"): ``pi P_1 = pi`` and so on down the product.
When every part can also leave a map as it is (a heat-bath update can: ``P_i(m, m) > 0`` on the support), the
cycle goes wherever one part goes, ``P(m, m') >= P_1(m, m') P_2(m', m') ... P_n(m', m') > 0``, so it is
irreducible as soon as one part is, and it can mix far faster than any of its parts.

Where it matters: a tile prior sampled by patch Gibbs over its tiles (the border prior of Section 5.2.3, a
patch table) moves only whole tiles, each drawn from a handful of configurations its table counted for
the current border; a configuration that straddles two tiles can then stay frozen for thousands of
sweeps. Single-cell Gibbs under a 1-given-8 table or an MRF is stuck the other way (one cell rarely turns
one counted pattern into another). ``KernelCycle([PatchGibbs(model, (3, 3)), CellGibbs(model)])`` makes both
kinds of move in every sweep, and ``KernelCycle([CellGibbs(model), PatchGibbs(model, (2, 2)),
PatchGibbs(model, (2, 2), offset=(1, 1))])`` adds small blocks to single cells; :func:`mixing_cycle` builds
the one that fits a prior's sampler. On held-out maps
(``ogm-ppl calibrate --kernel cycle``, docs/results.md) the chains of the backed-off 1-given-8 prior
from three different starts then agree on 99-100 % of the unseen cells (single-cell Gibbs: 12-38 %), and
those of the tempered backed-off border prior on 90 % of a HouseExpo map pair's, where patch Gibbs alone
leaves a quarter of them apart even after 10,000 sweeps.

:class:`KernelMixture` runs one part per sweep instead, drawn with fixed probabilities ``w_i``: the mixture
``P = sum_i w_i P_i`` keeps ``pi`` invariant as well (Tierney 1994, "mixtures"), at the cost of one part's sweep.

Every part keeps its own state; the cycle loads the current map into a part before its sweep (when the
map changed since that part last saw it) and reads the map back after it. The parts draw their random
numbers from torch's global generator in turn, so the state, the counters and
``torch.get_rng_state()`` determine the rest of the chain, as for any :class:`MapKernel`.
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Sequence

import numpy as np
import torch

from ogm_ppl.inference.mcmc.gibbs import CellGibbs, PatchGibbs
from ogm_ppl.inference.mcmc.kernel import KernelStateError, MapKernel

__all__ = ["KernelCycle", "KernelMixture", "mixing_cycle"]


class _Parts(MapKernel):
    """Several map kernels of one model on one map: the parts' hand-over, sampled cells, settings, diagnostics
    and checkpoints (``k{i}.*`` entries) that :class:`KernelCycle` and :class:`KernelMixture` share. A subclass
    writes :meth:`_sweep` from :meth:`_sweep_part`."""

    def __init__(self, kernels: Sequence[MapKernel], init=None) -> None:
        kernels = list(kernels)
        if not kernels:
            raise ValueError(f"a {type(self).__name__} needs at least one kernel")
        for i, k in enumerate(kernels):
            if not isinstance(k, MapKernel):
                raise TypeError(f"kernel {i} must be a MapKernel (CellGibbs, PatchGibbs, ...), got {type(k).__name__}")
            if k.model is not kernels[0].model:
                raise ValueError(f"kernel {i} samples another model than kernel 0: a cycle's parts share one model")
        if len({id(k) for k in kernels}) != len(kernels):
            raise ValueError("a kernel appears twice in the cycle: give each part its own instance")
        first = kernels[0]
        super().__init__(first.model, init=first.init if init is None else init, delta=first.delta)
        self.kernels = kernels
        self._own_init = init is not None
        self._stale = [True] * len(kernels)

    # ------------------------------------------------------------------ the MapKernel hooks
    def _set_up(self) -> None:
        """Nothing to set up: each part sets up its own sweeps."""

    def _initial_map(self) -> torch.Tensor:
        if self._own_init:
            return super()._initial_map()
        return self.model.full_map(self.kernels[0].initial_params[self.site]).to(torch.float64)

    def _load_map(self, m: np.ndarray) -> None:
        self.chain.bind(m)  # each part loads it before its next sweep (and keeps its own first hits)
        self._stale = [True] * len(self.kernels)

    @property
    def first_hit_state(self) -> np.ndarray:
        """Every ray's current first-occupied kappa (``R``), from the part that swept last."""
        for i in range(len(self.kernels)):
            if not self._stale[i]:
                return self.kernels[i].first_hit_state
        k = self.kernels[0]
        k._adopt_map(self.state)
        self._stale[0] = False
        return k.first_hit_state

    def sampled_cells(self) -> np.ndarray:
        """The union of the parts' sampled cells (sorted)."""
        return np.unique(np.concatenate([np.asarray(k.sampled_cells(), np.int64) for k in self.kernels]))

    def settings(self) -> dict:
        out = super().settings()
        out["kernels"] = [(type(k).__qualname__, k.settings()) for k in self.kernels]
        return out

    def _sweep_part(self, i: int) -> int:
        """One sweep of part ``i`` on the current map (handed over first if it changed since the part last saw
        it); the cells it changed."""
        k = self.kernels[i]
        if self._stale[i]:
            k._adopt_map(self.state)
        changes, updates = k.changes, k.updates
        k.sample(k.current_params())
        self.chain.updates += k.updates - updates
        moved = k.changes - changes
        if moved:
            self.state[:] = k.state
            self._stale = [j != i for j in range(len(self.kernels))]
        else:
            self._stale[i] = False
        return moved

    def logging(self):
        rates = [k.changes / max(k.updates, 1) for k in self.kernels]
        return OrderedDict([("sweeps", self.sweeps), ("change rates", " ".join(f"{r:.3f}" for r in rates))])

    def diagnostics(self):
        return {
            "sweeps": self.sweeps,
            "change rate": self.changes / max(self.updates, 1),
            "parts": [{"kind": type(k).__qualname__, **k.diagnostics()} for k in self.kernels],
        }

    # ------------------------------------------------------------------ checkpoints
    def _extra_state(self) -> dict[str, np.ndarray]:
        d: dict[str, np.ndarray] = {"parts": np.asarray(len(self.kernels), np.int64)}
        for i, k in enumerate(self.kernels):
            if self._stale[i]:  # a part that has not swept since the map changed (or at all) takes it now
                k._adopt_map(self.state)
                self._stale[i] = False
            d.update({f"k{i}.{key}": v for key, v in k.state_dict().items()})
        return d

    def _load_extra_state(self, state) -> None:
        n = np.asarray(state.get("parts", -1))
        if n.shape != () or n.dtype.kind not in "iu" or int(n) != len(self.kernels):
            raise KernelStateError(f"{type(self).__name__} state 'parts' must be {len(self.kernels)}, got {n!r}")
        for i, k in enumerate(self.kernels):
            part = {key[len(f"k{i}.") :]: v for key, v in state.items() if key.startswith(f"k{i}.")}
            try:
                k.load_state_dict(part)
            except KernelStateError as e:
                raise KernelStateError(f"{type(self).__name__} part {i}: {e}") from None


class KernelCycle(_Parts):
    """Sweeps of several map kernels in turn on one map (module docstring).

    Args:
        kernels: the parts (:class:`~ogm_ppl.inference.mcmc.kernel.MapKernel` s of the *same* model, e.g.
            ``[PatchGibbs(model, (3, 3)), CellGibbs(model)]``); one sweep of the cycle is one sweep of each,
            in this order. Their checkpoint entries are the cycle's ``k{i}.*`` entries.
        init: the starting map: ``None`` (default) uses the first part's (its ``init``), otherwise any start
            :func:`~ogm_ppl.inference.mcmc.kernel.initial_map` knows (``"ogm"``, ``"free"``, ``"prior"``, a map).

    The cycle samples the cells its parts sample (:meth:`sampled_cells`: their union); with parts given a
    ``region``, the others keep their values.

    >>> from ogm_ppl.inference.mcmc import CellGibbs, PatchGibbs
    >>> from ogm_ppl.testing.kernels import enumerable_2d
    >>> model = enumerable_2d()
    >>> k = KernelCycle([PatchGibbs(model, (1, 2)), CellGibbs(model)])
    >>> k.setup(); params = k.sample(k.current_params())
    >>> k.sweeps, [p.sweeps for p in k.kernels]
    (1, [1, 1])
    """

    def _sweep(self) -> int:
        return sum(self._sweep_part(i) for i in range(len(self.kernels)))


class KernelMixture(_Parts):
    r"""A random choice of one map kernel per sweep (a mixture, Tierney 1994): ``P = sum_i w_i P_i``.

    Each sweep draws part ``i`` with probability ``w_i`` from torch's global generator and runs one sweep of
    it; if every part leaves ``pi`` invariant, so does the mixture (``pi P = sum_i w_i pi P_i = pi``). It costs
    one part's sweep where a :class:`KernelCycle` of the same parts costs all of them, and it can sit inside a
    cycle as one of its parts (e.g. one of several shifted tilings per sweep: ``mixing_cycle(...,
    shifted="random")``).

    Args:
        kernels: the parts (map kernels of the *same* model), as for :class:`KernelCycle`.
        weights: ``w`` (``n``, positive, normalised here); ``None`` (default): ``1 / n`` each.
        init: the starting map, as for :class:`KernelCycle`.

    Its parts' checkpoint entries are ``k{i}.*``, as a cycle's, with the weights beside them (a checkpoint of
    other weights is refused).

    ``sweeps`` counts the mixture's sweeps; each part's own ``sweeps`` counts the times it was drawn.

    >>> from ogm_ppl.inference.mcmc import CellGibbs, PatchGibbs
    >>> from ogm_ppl.testing.kernels import enumerable_2d
    >>> model = enumerable_2d()
    >>> k = KernelMixture([PatchGibbs(model, (1, 2)), CellGibbs(model)], weights=[0.25, 0.75])
    >>> k.setup(); params = k.sample(k.current_params())
    >>> k.sweeps, sum(p.sweeps for p in k.kernels)
    (1, 1)
    """

    def __init__(self, kernels: Sequence[MapKernel], weights: Sequence[float] | None = None, init=None) -> None:
        super().__init__(kernels, init=init)
        n = len(self.kernels)
        w = np.full(n, 1.0 / n) if weights is None else np.asarray(weights, dtype=np.float64)
        if w.shape != (n,) or not np.all(np.isfinite(w)) or np.any(w <= 0):
            raise ValueError(f"weights must be {n} positive finite numbers, one per kernel, got {weights!r}")
        self.weights = w / w.sum()
        self._cum = torch.from_numpy(np.cumsum(self.weights))

    def settings(self) -> dict:
        out = super().settings()
        out["weights"] = [float(v) for v in self.weights]
        return out

    def _extra_state(self) -> dict[str, np.ndarray]:
        return {**super()._extra_state(), "weights": self.weights.copy()}

    def _load_extra_state(self, state) -> None:
        w = np.asarray(state.get("weights", np.zeros(0)))
        if w.shape != self.weights.shape or w.dtype.kind != "f" or not np.allclose(w, self.weights, rtol=0, atol=1e-15):
            raise KernelStateError(f"KernelMixture state 'weights' must be {self.weights.tolist()}, got {w!r}")
        super()._load_extra_state(state)

    def _sweep(self) -> int:
        u = torch.rand((), dtype=torch.float64)
        return self._sweep_part(min(int(torch.searchsorted(self._cum, u, right=True)), len(self.kernels) - 1))


def mixing_cycle(
    model, patch: tuple[int, int] | int | None = None, init="ogm", shifted: bool | str = False
) -> KernelCycle:
    """The cycle that adds to a prior's Gibbs sampler the moves it lacks (module docstring).

    ``patch`` given (a tile prior sampled by patch Gibbs over its ``h x w`` tiles): a sweep of those patches,
    then a single-cell Gibbs sweep. ``patch=None`` (single-cell Gibbs): a single-cell sweep, then 2 x 2 patches
    on the tiling at offset 0 and on the one offset by a cell. ``init`` is the first part's start.

    ``shifted=True`` (with ``patch``) also sweeps ``h x w`` patches on the tilings shifted by ``d`` cells down
    and right from the prior's (``d = 1 .. min(h, w) - 1``): each such patch straddles four tiles, so it can
    turn a pattern that no tile update or single cell undoes. Such a patch is drawn from its full conditional
    over all ``2^(h w)`` configurations (a 3 x 3 patch: 512), so these sweeps cost far more than the tile
    sweeps they follow. ``shifted="random"`` sweeps one of those shifted tilings per sweep instead, drawn
    uniformly (a :class:`KernelMixture` as the cycle's last part): the same moves at a fraction of their
    cost per sweep (one over the number of shifted tilings).
    """
    if shifted not in (False, True, "random"):
        raise ValueError(f"shifted must be False, True or 'random', got {shifted!r}")
    if patch is None:
        if shifted:
            raise ValueError("shifted=True needs the tile shape (patch=(h, w))")
        parts = [CellGibbs(model, init=init), PatchGibbs(model, (2, 2)), PatchGibbs(model, (2, 2), offset=(1, 1))]
    else:
        parts = [PatchGibbs(model, patch, init=init), CellGibbs(model)]
        if shifted:
            h, w = (1, int(patch)) if isinstance(patch, (int, np.integer)) else (int(patch[0]), int(patch[1]))
            c = model.prior.compiled()  # where the prior's tiling starts (a tempered prior's too)
            o = (int(getattr(c, "t_r0", 0)), int(getattr(c, "t_c0", 0)))
            shifts = range(1, (w if h == 1 else min(h, w)))
            moves = [PatchGibbs(model, patch, offset=(o[0] + (d if h > 1 else 0), o[1] + d)) for d in shifts]
            parts += [KernelMixture(moves)] if shifted == "random" and len(moves) > 1 else moves
    return KernelCycle(parts)
