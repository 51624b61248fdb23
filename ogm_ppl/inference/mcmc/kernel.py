r"""The map-kernel base: the protocol every MCMC kernel over whole maps follows (Chapter 4).

:class:`MapKernel` is a Pyro :class:`~pyro.infer.mcmc.mcmc_kernel.MCMCKernel`, driven by
``pyro.infer.MCMC`` (``setup``, ``initial_params``, ``sample``, ``logging``, ``diagnostics``) or by
:func:`~ogm_ppl.inference.mcmc.runner.run_gibbs`. Its protocol:

* **Site** ``"m"``: the latent (not pinned) cells of the map, float64 0/1, shape ``(L,)`` in
  ``model.latent`` order (``model.full_map`` restores the ``K`` cells).
* **State** (:attr:`MapKernel.state`): the current full map, a live ``(K,)`` uint8 0/1 array with the
  pinned cells 0 (copy it to keep it). It lives, with every ray's first hit, the counters and the value
  returned last, in the kernel's :class:`~ogm_ppl.inference.mcmc.chain_state.ChainState`
  (:attr:`MapKernel.chain`). Random numbers come from torch's global generator only, so the state, the
  counters and ``torch.get_rng_state()`` determine the rest of the chain.
* **Params in step**: ``sample(params)`` re-reads ``params["m"]`` unless it is the very tensor the kernel
  returned last; a runner that holds no params asks :meth:`MapKernel.current_params` for them (a set-up
  or restored kernel), and :meth:`MapKernel.set_state` loads any map.
* **Checkpoints**: :meth:`MapKernel.state_dict` is a flat ``dict[str, np.ndarray]`` (savable by
  ``np.savez`` and read back with ``allow_pickle=False``): ``format`` (int64, :attr:`STATE_FORMAT`),
  ``kind`` (the class name), ``m`` (the state, ``(K,)`` uint8), ``sweeps``, ``changes`` and ``updates``
  (int64 counters), and a subclass's extra entries. :meth:`MapKernel.load_state_dict` checks every entry
  and raises :class:`KernelStateError` naming what is wrong; a kernel built with the same arguments that
  loads it continues the chain bit for bit.

A subclass implements ``_sweep()`` (one sweep from the current state ``self.state``, drawing from torch's
generator; adds its number of updates to ``self.chain.updates`` and returns the number that changed the map;
a sweep that changes the map keeps every ray's first occupied cell ``self.chain.f`` in step, or calls
``self._load_map(self.state)`` at its end, which recomputes it) and may
extend ``_set_up()`` (one-time set-up, run once by ``_prepare()``), ``_load_map(m)`` (rebuild state derived
from the map, a checked ``(K,)`` uint8 array; call ``super()``, which binds ``m`` and its first hits to the
chain: composite kernels hand maps over through it without re-checking them), ``_extra_state()`` /
``_load_extra_state(state)`` (more checkpoint entries) and ``_initial_map()`` (a ``K`` starting map). A
composite kernel drives its parts through their public methods (:meth:`MapKernel.step`,
:meth:`MapKernel.set_state`, :attr:`MapKernel.state`) and hands maps between them with
:meth:`MapKernel._adopt_map`. Public attributes are settings (the checkpoint's fingerprint reads them once, as
the kernel was built): counters a sweep updates are private, checkpointed through ``_extra_state``. The
model's ray index (``model.ray_index()``) and ``model.log_joint`` give what a sweep needs to score a change.
``ogm_ppl.testing.KernelContract`` checks a kernel against this protocol and the exact posterior.
"""

from __future__ import annotations

import warnings
from collections import OrderedDict
from collections.abc import Mapping

import numpy as np
import torch
from pyro.infer.mcmc.mcmc_kernel import MCMCKernel

from ogm_ppl.inference._kernels.cells import first_hits, gather_as_float
from ogm_ppl.inference.mcmc.chain_state import ChainState
from ogm_ppl.inference.mcmc.fingerprint import digest
from ogm_ppl.models.occupancy import OccupancyModel

__all__ = ["KernelStateError", "MapKernel", "MasslessStartWarning", "check_start", "initial_map", "region_cells"]

SCANS = ("random", "permutation", "systematic")
#: the starting maps :func:`initial_map` knows by name (besides ``"guide:CORPUS"``)
START_MAPS = ("ogm", "prior", "occupied", "free")


class MasslessStartWarning(UserWarning):
    """A chain starts from a map the prior gives zero mass (an unsmoothed table's never-counted
    configuration): its first sweeps move through massless states, and where they settle depends on that
    start. A backed-off prior (``KIND_bo``) or another start avoids it."""


def ogm_start_threshold(prior) -> float:
    """The occupancy at which the thresholded-OGM start cuts (:func:`initial_map`): the prior's mean cell
    occupancy (``sigmoid`` of its cell log-odds where it has them), else its ``mean_occupancy``, else 0.5."""
    lo = prior.cell_log_odds()
    return float(torch.sigmoid(lo).mean()) if lo is not None else float(getattr(prior, "mean_occupancy", 0.5))


def check_start(init) -> None:
    """Refuse (:class:`ValueError`) a starting map :func:`initial_map` would refuse by its name: a string
    other than :data:`START_MAPS`, or ``"guide:CORPUS"`` for a corpus with no shipped guide (checked by name,
    the guide is not loaded), or a bool or number (a map is a sequence or tensor of cells; ``True`` given
    positionally where another argument was meant would otherwise fail later on its shape). Maps are checked
    against the model when used."""
    if isinstance(init, bool | int | float):
        names = ", ".join(map(repr, (*START_MAPS, "guide:CORPUS")))
        raise ValueError(f"init must be {names} or a map of cells, got {init!r}")
    if not isinstance(init, str):
        return
    if init.startswith("guide:"):
        from ogm_ppl.inference.variational.amortised import corpus_guides, unknown_corpus_message

        corpus = init.removeprefix("guide:")
        if corpus not in corpus_guides():
            raise ValueError(f"init {init!r}: {unknown_corpus_message(corpus)}")
    elif init not in START_MAPS:
        names = ", ".join(map(repr, (*START_MAPS, "guide:CORPUS")))
        raise ValueError(f"init must be {names} or a map, got {init!r}")


def initial_map(model: OccupancyModel, init="ogm", delta="haehnel", threshold: float | None = None) -> torch.Tensor:
    """A starting map (``K`` float 0/1; pinned cells free).

    ``init``: ``"ogm"`` — traditional OGM thresholded at the cell prior (Section 4.1.2; ``delta`` names the
    update term, ``threshold`` defaults to the mean prior occupancy or 0.5); ``"prior"`` — a draw from the
    prior; ``"occupied"``; ``"free"``; ``"guide:CORPUS"`` — the mode ``q_k > 1/2`` of the amortised guide
    learned on a corpus (:func:`~ogm_ppl.inference.variational.corpus_guide`); or a ``K`` map.
    """
    K = model.num_cells
    check_start(init)
    if isinstance(init, str):
        if init == "ogm":
            from ogm_ppl.inference.log_odds.maps import evidence_grid
            from ogm_ppl.models.delta import delta_by_name

            thr = threshold if threshold is not None else ogm_start_threshold(model.prior)
            d = delta_by_name(delta) if isinstance(delta, str) else delta
            m = (evidence_grid(model.rays, d, check_setting=False).probabilities > thr).to(torch.float64)
        elif init == "prior":
            m = model.prior.sample().to(torch.float64)
        elif init == "occupied":
            m = torch.ones(K, dtype=torch.float64)
        elif init.startswith("guide:"):
            from ogm_ppl.inference.variational.amortised import corpus_guide

            m = (corpus_guide(init.removeprefix("guide:")).marginals(model) > 0.5).to(torch.float64)
        else:  # "free": check_start refused any other name
            m = torch.zeros(K, dtype=torch.float64)
    else:
        m = torch.as_tensor(init).flatten().clone()
        m = model.check_maps(model.full_map(m) if m.shape != (K,) else m, what="init map").clone()
    m[model.known_free] = 0.0
    return m


def region_cells(model: OccupancyModel, region) -> np.ndarray | None:
    """``region`` (``None``; a boolean mask of ``K`` cells or of the grid's shape; or cell indices) as sorted
    unique cell indices, checked: right shape, boolean or integer, in range, non-empty, holding a latent cell."""
    if region is None:
        return None
    r = region.detach().cpu().numpy() if isinstance(region, torch.Tensor) else np.asarray(region)
    K = model.num_cells
    if r.size == 0:
        raise ValueError("region is empty")
    if r.dtype == np.bool_:
        if r.shape not in ((K,), tuple(model.grid.shape)):
            raise ValueError(f"region mask must have shape ({K},) or {tuple(model.grid.shape)}, got {r.shape}")
        cells = np.flatnonzero(r.ravel())
    elif np.issubdtype(r.dtype, np.integer):
        if r.ndim != 1:
            raise ValueError(f"region indices must be a 1D array of cells, got shape {r.shape}")
        if r.size and (r.min() < 0 or r.max() >= K):
            raise ValueError(f"region indices must lie in [0, {K}), got {int(r.min())}..{int(r.max())}")
        cells = np.unique(r)
    else:
        raise ValueError(f"region must be a boolean mask or integer cell indices, got dtype {r.dtype}")
    if cells.size == 0:
        raise ValueError("region is empty")
    if model.known_free.numpy()[cells].all():
        raise ValueError("region holds no latent cell (every region cell is pinned known-free)")
    return np.ascontiguousarray(cells, dtype=np.int64)


class KernelStateError(ValueError):
    """A kernel state (``load_state_dict``) that this kernel cannot take: the message names the entry."""


_STATE_KEYS = ("format", "kind", "m", "sweeps", "changes", "updates")
_DYNAMIC = {"model", "transforms"}


class MapKernel(MCMCKernel):
    """Base of the MCMC kernels over whole maps (protocol: module docstring).

    Args:
        model: an :class:`~ogm_ppl.OccupancyModel`.
        scan: ``"systematic"``, ``"permutation"`` or ``"random"`` (the order of the updates in a sweep).
        init: the starting map, see :func:`initial_map`; a name is checked here (:func:`check_start`).
        delta: the OGM update term for ``init="ogm"``.
        region: ``None`` or the cells to sample (:func:`region_cells`); the others keep their values, so
            the chain samples ``p(m_R' | m_rest, z)`` with ``R'`` = :meth:`sampled_cells`.
    """

    site = "m"
    STATE_FORMAT = 1

    def __init__(
        self, model: OccupancyModel, scan: str = "systematic", init="ogm", delta="haehnel", region=None
    ) -> None:
        if not isinstance(model, OccupancyModel):
            hint = " (pass the OccupancyModel itself, not its model function)" if callable(model) else ""
            raise TypeError(f"{type(self).__name__} takes an OccupancyModel, got {type(model).__name__}{hint}")
        if scan not in SCANS:
            raise ValueError(f"scan must be one of {SCANS}, got {scan!r}")
        check_start(init)
        self.model = model
        self.region = region_cells(model, region)  # sorted cell indices, or None: every cell
        latent = model.latent.numpy().astype(np.int64)
        self._visit = latent if self.region is None else latent[np.isin(latent, self.region)]  # latent ∩ region
        self.scan = scan
        self.init = init
        self.delta = delta
        self.transforms: dict = {}
        self._initial_params: dict[str, torch.Tensor] | None = None
        self._ready = False
        self._start_checked = False
        self._chain = ChainState()
        super().__init__()

    # --------------------------------------------------------------- set-up
    def _prepare(self) -> None:
        """Set the kernel up, once: the latent and pinned cells, then :meth:`_set_up`."""
        if self._ready:
            return
        self._latent = self.model.latent.numpy().astype(np.int64)
        self._pinned = self.model.known_free.numpy().astype(np.uint8)
        self._set_up()
        self._ready = True

    def _set_up(self) -> None:
        """Hook: the one-time set-up of what the sweeps read (extend it with ``super()``): here the model's ray
        index and its prior's compiled face."""
        model = self.model
        # the ray index and the prior's compiled face (None: the generic path), read by the compiled sweeps
        self._index = index = model.ray_index()
        self._compiled = model.prior.compiled()
        # the same arrays under their own names (read by tests and benchmarks)
        self._offsets, self._cells, self._ll = index.offsets, index.cells, index.ll
        self._c_off, self._c_ray, self._c_kappa = index.c_off, index.c_ray, index.c_kappa
        lo = model.prior.cell_log_odds()
        self._prior_lo = None if lo is None else np.ascontiguousarray(lo.numpy(), dtype=np.float64)
        self._local = self._compiled if lo is None else None

    def _initial_map(self) -> torch.Tensor:
        """Hook: the ``K`` starting map (float 0/1) when no ``initial_params`` are given."""
        return initial_map(self.model, self.init, self.delta)

    def setup(self, warmup_steps=0, *args, **kwargs) -> None:
        """Set up (once), load the initial params as the state and start the counts of :meth:`diagnostics`
        afresh (``MCMC`` calls this at the start of each chain); warns (:class:`MasslessStartWarning`, once per
        kernel) when the prior can give a map zero mass and gives the starting map zero mass.

        ``args`` / ``kwargs`` are what ``MCMC.run(*args, **kwargs)`` passes for the model; this kernel samples
        the posterior of the model it was built with, readings included, so any is refused (``ValueError``)
        rather than ignored."""
        if args or kwargs:
            raise ValueError(
                f"{type(self).__name__} samples the model it was built with (its readings fixed there), so "
                f"MCMC.run() takes no model arguments; got {len(args)} positional and {sorted(kwargs)} keyword. "
                "For other readings build an OccupancyModel of them (raycast of their Scans) and a kernel of it."
            )
        self._chain.restart()
        self._prepare()
        m = self.initial_params[self.site]
        self._set_state(m)
        if getattr(self.model.prior, "can_be_zero", False) and not self._start_checked:
            self._start_checked = True
            full = self.model.full_map(torch.as_tensor(m, dtype=torch.float64))
            if float(self.model.prior.log_prob(full)) == -float("inf"):
                warnings.warn(
                    MasslessStartWarning(
                        f"{type(self).__name__}: the starting map has zero mass under the prior "
                        f"{type(self.model.prior).__name__} (a configuration its table never counted); the chain "
                        "moves through massless states until it reaches the prior's support, and where it settles "
                        "depends on this start. A backed-off prior (KIND_bo) or another init avoids it."
                    ),
                    stacklevel=2,
                )

    @property
    def initial_params(self) -> dict[str, torch.Tensor]:
        """``{"m": (L,) float64}``: given by the setter, else :meth:`_initial_map`'s latent cells."""
        if self._initial_params is None:
            m = torch.as_tensor(self._initial_map(), dtype=torch.float64)
            self._initial_params = {self.site: m[self.model.latent]}
        return self._initial_params

    @initial_params.setter
    def initial_params(self, params) -> None:
        if not isinstance(params, dict) or self.site not in params:
            got = sorted(params) if isinstance(params, dict) else type(params).__name__
            raise ValueError(
                f"{type(self).__name__}: initial_params must be a dict with the site {self.site!r} (the latent "
                f"cells, or a full map), got {got}"
            )
        self._initial_params = params

    def _set_state(self, m) -> None:
        """Hook: check map ``m`` (``K`` or ``L`` values, 0/1) and load it as the state (:meth:`_load_map`)."""
        m = self.model.check_maps(self.model.full_map(torch.as_tensor(m).detach().cpu()), what="kernel state")
        arr = np.ascontiguousarray((m.numpy() != 0).astype(np.uint8))
        arr[self._pinned.astype(bool)] = 0
        self._load_map(arr)

    def _load_map(self, m: np.ndarray) -> None:
        """Hook: make the checked map ``m`` (``(K,)`` uint8 0/1, pinned cells 0; owned by the kernel from now on)
        the state (bound to :attr:`chain` with its first hits); extend to rebuild derived state."""
        self._chain.bind(m, first_hits(m, self._offsets, self._cells))

    def _adopt_map(self, m: np.ndarray) -> None:
        """Load the state another kernel of the same model holds (``(K,)`` uint8 0/1, pinned cells 0; copied),
        skipping the checks of :meth:`set_state`: the hand-over of composite kernels (a cycle's parts, a
        tempering swap). A kernel that extends ``_set_state`` itself gets the checked path."""
        self._prepare()
        if type(self)._set_state is MapKernel._set_state:
            self._load_map(np.array(m, dtype=np.uint8, copy=True))
        else:
            self._set_state(torch.from_numpy(np.asarray(m).astype(np.float64)))

    def set_state(self, m) -> None:
        """Make map ``m`` (``K`` cells or site ``"m"``'s ``L``; 0/1) the current state."""
        self._prepare()
        self._set_state(m)

    @property
    def chain(self) -> ChainState:
        """The chain's state (:class:`~ogm_ppl.inference.mcmc.chain_state.ChainState`): the map, the first hits,
        the counters and the value returned last. The kernel owns it: a subclass's sweep writes the map in place
        and adds its updates to ``chain.updates``; loading maps and counting sweeps are the base's."""
        return self._chain

    @property
    def state(self) -> np.ndarray:
        """The current full map (live ``(K,)`` uint8 array; site ``"m"`` carries its latent cells)."""
        m = self._chain.m
        if m is None:
            raise RuntimeError(
                f"{type(self).__name__} has no state yet: call setup(), set_state() or load_state_dict() first"
            )
        return m

    def current_params(self) -> dict[str, torch.Tensor]:
        """``{"m": (L,) float64}`` of the current state, recognised by the next :meth:`sample` as the
        kernel's own (no re-read): how a runner starts a chain from a set-up or restored kernel."""
        self._prepare()
        out = torch.from_numpy(gather_as_float(self.state, self._latent))
        self._chain.last = out
        return {self.site: out}

    @property
    def first_hit_state(self) -> np.ndarray:
        """Every ray's current first-occupied kappa (``R``)."""
        f = self._chain.f
        if f is None:
            raise RuntimeError(
                f"{type(self).__name__} keeps no first hits: it has no state yet, or its parts sweep and keep them"
            )
        return f

    def sampled_cells(self) -> np.ndarray:
        """The cells ``R'`` the kernel can change (sorted): with ``region``, the chain samples
        ``p(m_R' | m_rest, z)`` and every other cell keeps its value. Latent ∩ region for cell kernels."""
        return self._visit

    @property
    def sweeps(self) -> int:
        """Sweeps since the start of the chain."""
        return self._chain.sweeps

    @property
    def changes(self) -> int:
        """Updates that changed the map, since the start of the chain."""
        return self._chain.changes

    @property
    def updates(self) -> int:
        """Updates made (cell or patch updates, proposals), since the start of the chain."""
        return self._chain.updates

    def settings(self) -> dict:
        """The public settings (simple values; arrays as digests) that a checkpoint's fingerprint sees.

        Read once, at the first call (before the first checkpoint of a run: the kernel as built), and kept:
        a public attribute a subclass updates while it samples (a counter) would otherwise make the same
        chain's next checkpoint look like another kernel's. Counters belong in private attributes and, to be
        checkpointed, in ``_extra_state``."""
        cached = self.__dict__.get("_settings_at_start")
        if cached is not None:
            return dict(cached)
        out = {}
        for k, v in sorted(vars(self).items()):
            if k.startswith("_") or k in _DYNAMIC:
                continue
            if isinstance(v, (bool, int, float, str, tuple, type(None))):
                out[k] = v
            elif isinstance(v, (torch.Tensor, np.ndarray)):
                out[k] = digest(v)
        self._settings_at_start = dict(out)
        return out

    # --------------------------------------------------------------- sampling
    def sample(self, params):
        """One sweep from ``params["m"]`` (or from the state, if ``params`` are the kernel's own)."""
        self._prepare()
        m = params[self.site]
        if m is not self._chain.last:
            self._set_state(m)
        self.step()
        return self.current_params()

    def step(self) -> int:
        """One sweep from the current state, counted; returns the number of updates that changed the map. What
        :meth:`sample` does once its params are loaded: a composite kernel sweeps its parts through it."""
        self._prepare()
        changes = self._sweep()
        self._chain.swept(changes)
        return changes

    def _sweep(self) -> int:
        """Hook: one sweep from the current state (module docstring); returns the number of changes."""
        raise NotImplementedError

    def _order(self, items: np.ndarray) -> np.ndarray:
        n = len(items)
        if self.scan == "systematic":
            return items
        if self.scan == "permutation":
            return np.ascontiguousarray(items[torch.randperm(n).numpy()])
        return np.ascontiguousarray(items[torch.randint(0, n, (n,)).numpy()]) if n else items

    def _uniforms(self, n: int) -> np.ndarray:
        return torch.rand(n, dtype=torch.float64).numpy()

    def logging(self):
        c = self._chain
        return OrderedDict([("sweeps", c.sweeps), ("change rate", f"{c.changes / max(c.updates, 1):.3f}")])

    def diagnostics(self):
        c = self._chain
        return {"sweeps": c.sweeps, "change rate": c.changes / max(c.updates, 1)}

    # --------------------------------------------------------------- checkpoints
    def state_dict(self) -> dict[str, np.ndarray]:
        """The kernel's state as flat arrays (module docstring), extras from :meth:`_extra_state`."""
        d = {
            "format": np.asarray(self.STATE_FORMAT, np.int64),
            "kind": np.asarray(type(self).__qualname__),
            "m": self.state.copy(),
            "sweeps": np.asarray(self._chain.sweeps, np.int64),
            "changes": np.asarray(self._chain.changes, np.int64),
            "updates": np.asarray(self._chain.updates, np.int64),
        }
        extra = self._extra_state()
        clash = sorted(set(extra) & set(d))
        if clash:
            raise KeyError(f"{type(self).__name__}._extra_state() reuses the base entries {clash}")
        d.update(extra)
        return d

    def _extra_state(self) -> dict[str, np.ndarray]:
        """Hook: more checkpoint entries (arrays, no objects)."""
        return {}

    def _load_extra_state(self, state: Mapping) -> None:
        """Hook: check and load the entries of :meth:`_extra_state` (raise :class:`KernelStateError`)."""

    def load_state_dict(self, state: Mapping) -> None:
        """Check ``state`` (from :meth:`state_dict`) and make it the kernel's; the next sweep continues the
        chain it was taken from. Raises :class:`KernelStateError` naming the bad entry."""
        name = type(self).__qualname__
        if not isinstance(state, Mapping):
            raise KernelStateError(f"a {name} state is a mapping of arrays, got {type(state).__name__}")
        missing = [k for k in _STATE_KEYS if k not in state]
        if missing:
            raise KernelStateError(f"{name} state lacks {', '.join(missing)}")
        fmt = _count(state, "format")
        if fmt != self.STATE_FORMAT:
            raise KernelStateError(f"{name} state of format {fmt}, this kernel reads format {self.STATE_FORMAT}")
        kind = np.asarray(state["kind"])
        if kind.shape != () or kind.dtype.kind != "U" or str(kind) != name:
            raise KernelStateError(f"a state of a {kind!s} kernel cannot be loaded into a {name}")
        m = np.asarray(state["m"])
        K = self.model.num_cells
        if m.shape != (K,):
            raise KernelStateError(f"{name} state 'm' must have shape ({K},), got {m.shape}")
        if m.dtype.kind not in "biuf" or not np.isin(m, (0, 1)).all():
            raise KernelStateError(f"{name} state 'm' must hold 0/1 values")
        if m[self.model.known_free.numpy()].any():
            raise KernelStateError(f"{name} state 'm' occupies a pinned (known-free) cell")
        counts = {k: _count(state, k) for k in ("sweeps", "changes", "updates")}
        self._prepare()
        self._load_extra_state(state)
        self._set_state(torch.from_numpy(m.astype(np.float64)))
        self._chain.restart(**counts)


def _count(state: Mapping, key: str) -> int:
    v = np.asarray(state[key])
    if v.shape != () or v.dtype.kind not in "iu" or int(v) < 0:
        raise KernelStateError(f"kernel state {key!r} must be a non-negative integer, got {v!r}")
    return int(v)
