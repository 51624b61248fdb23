r"""The map-kernel base: the protocol every MCMC kernel over whole maps follows (Chapter 4).

:class:`MapKernel` is a Pyro :class:`~pyro.infer.mcmc.mcmc_kernel.MCMCKernel` whose single site ``"m"``
holds the latent (not pinned) cells of the map as float 0/1 (``L``, in ``model.latent`` order). It keeps the
full map (``K`` uint8) and every ray's first occupied kappa (``R``) in step, draws its random numbers from
torch's global generator, and saves / restores itself through ``state_dict`` / ``load_state_dict``.
Subclasses implement ``_sweep()`` (one sweep; returns the number of changed updates).
"""

from __future__ import annotations

from collections import OrderedDict

import numpy as np
import torch
from pyro.infer.mcmc.mcmc_kernel import MCMCKernel

from ogm_ppl.inference._kernels.cells import first_hits
from ogm_ppl.models.occupancy import OccupancyModel

__all__ = ["MapKernel", "initial_map", "region_cells"]

SCANS = ("random", "permutation", "systematic")

def initial_map(model: OccupancyModel, init="ogm", delta="haehnel", threshold: float | None = None) -> torch.Tensor:
    """A starting map (``K`` float 0/1; pinned cells free).

    ``init``: ``"ogm"`` — traditional OGM thresholded at the cell prior (Section 4.1.2; ``delta`` names the
    update term, ``threshold`` defaults to the mean prior occupancy or 0.5); ``"prior"`` — a draw from the
    prior; ``"occupied"``; ``"free"``; or a ``K`` map.
    """
    K = model.num_cells
    if isinstance(init, str):
        if init == "ogm":
            from ogm_ppl.inference.log_odds.maps import evidence_grid
            from ogm_ppl.models.delta import delta_by_name

            lo = model.prior.cell_log_odds()
            mean = float(torch.sigmoid(lo).mean()) if lo is not None else getattr(model.prior, "mean_occupancy", 0.5)
            thr = threshold if threshold is not None else mean
            d = delta_by_name(delta) if isinstance(delta, str) else delta
            m = (evidence_grid(model.rays, d).probabilities > thr).to(torch.float64)
        elif init == "prior":
            m = model.prior.sample().to(torch.float64)
        elif init == "occupied":
            m = torch.ones(K, dtype=torch.float64)
        elif init == "free":
            m = torch.zeros(K, dtype=torch.float64)
        else:
            raise ValueError(f"init must be 'ogm', 'prior', 'occupied', 'free' or a map, got {init!r}")
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


class MapKernel(MCMCKernel):
    """Shared state handling: the map, every ray's first hit, and sync with Pyro's ``params``."""

    site = "m"

    def __init__(self, model: OccupancyModel, scan: str = "systematic", init="ogm", delta="haehnel",
                 region=None) -> None:  # fmt: skip
        if scan not in SCANS:
            raise ValueError(f"scan must be one of {SCANS}, got {scan!r}")
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
        self._last = None
        self.sweeps = 0
        self._changes = 0
        self._updates = 0
        super().__init__()

    # --------------------------------------------------------------- set-up
    def _prepare(self) -> None:
        if self._ready:
            return
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
        self._latent = model.latent.numpy().astype(np.int64)
        self._pinned = model.known_free.numpy().astype(np.uint8)
        self._ready = True

    def _latent_values(self, m: torch.Tensor) -> torch.Tensor:
        """Site ``"m"`` holds the latent (not pinned) cells only (``L``), in ``model.latent`` order."""
        return m[self.model.latent]

    def setup(self, warmup_steps=0, *args, **kwargs) -> None:
        self._prepare()
        if self._initial_params is None:
            self._initial_params = {self.site: self._latent_values(initial_map(self.model, self.init, self.delta))}
        self._set_state(self._initial_params[self.site])

    @property
    def initial_params(self):
        if self._initial_params is None:
            self._initial_params = {self.site: self._latent_values(initial_map(self.model, self.init, self.delta))}
        return self._initial_params

    @initial_params.setter
    def initial_params(self, params):
        self._initial_params = params

    def _set_state(self, m) -> None:
        m = self.model.check_maps(self.model.full_map(torch.as_tensor(m).detach().cpu()), what="kernel state")
        self._m = np.ascontiguousarray((m.numpy() != 0).astype(np.uint8))
        self._m[self._pinned.astype(bool)] = 0
        self._f = first_hits(self._m, self._offsets, self._cells)
        self._last = None

    @property
    def state(self) -> np.ndarray:
        """The current full map (uint8, ``K``; site ``"m"`` carries its latent cells, ``model.full_map``)."""
        return self._m

    @property
    def first_hit_state(self) -> np.ndarray:
        """Every ray's current first-occupied kappa (``R``)."""
        return self._f

    def sampled_cells(self) -> np.ndarray:
        """The cells ``R'`` the kernel can change (sorted): with ``region``, the chain samples
        ``p(m_R' | m_rest, z)`` and every other cell keeps its value. Latent ∩ region for cell kernels."""
        return self._visit

    # --------------------------------------------------------------- sampling
    def sample(self, params):
        self._prepare()
        m = params[self.site]
        if m is not self._last:
            self._set_state(m)
        self._changes += self._sweep()
        self.sweeps += 1
        out = torch.from_numpy(self._m[self._latent].astype(np.float64))  # site "m": the latent cells
        self._last = out
        return {self.site: out}

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
        rate = self._changes / max(self._updates, 1)
        return OrderedDict([("sweeps", self.sweeps), ("change rate", f"{rate:.3f}")])

    def diagnostics(self):
        return {"sweeps": self.sweeps, "change rate": self._changes / max(self._updates, 1)}

    # --------------------------------------------------------------- checkpoints
    def state_dict(self) -> dict:
        return {"m": self._m.copy(), "sweeps": self.sweeps, "changes": self._changes, "updates": self._updates}

    def load_state_dict(self, state: dict) -> None:
        self._prepare()
        self._set_state(torch.from_numpy(np.asarray(state["m"])))
        self.sweeps = int(state["sweeps"])
        self._changes = int(state["changes"])
        self._updates = int(state["updates"])
