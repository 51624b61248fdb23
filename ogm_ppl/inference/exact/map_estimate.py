r"""A mode of the posterior by hill-climbing (Section 2.2): iterated conditional modes with the forward model.

Each cell in turn takes the value that maximises its conditional posterior given all other cells

.. math:: l(m_k \mid z, m_{-k}) = l(m_k \mid m_{-k})
          + \sum_n \log \frac{p(z_n \mid m_{-k}, m_k = 1)}{p(z_n \mid m_{-k}, m_k = 0)} \quad (2.4)

(occupied if positive, free if negative, unchanged on a tie), sweeping until nothing changes: a local
maximum of the joint, not necessarily the MAP map (the global maximum): different starts can end in
different local maxima. On a problem small enough to enumerate, ``brute_force(model).mode()`` (or Pyro's
``infer_discrete(model.model_per_cell, temperature=0)``) is the MAP. The thesis initialises all cells occupied
so that unobserved cells reflect the sensor (needed by the offline patch map, Section 3.2); all-free and random
starts are available too.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from ogm_ppl._validate import as_binary_maps
from ogm_ppl.inference._kernels import cell_sweep as cs
from ogm_ppl.models.occupancy import OccupancyModel

__all__ = ["MapEstimate", "map_estimate"]


@dataclass(frozen=True)
class MapEstimate:
    """The local maximum reached (``K`` float 0/1), its log joint, and how many sweeps it took."""

    map: torch.Tensor
    log_joint: float
    sweeps: int
    converged: bool


def _initial(model: OccupancyModel, init, seed) -> np.ndarray:
    K = model.num_cells
    if isinstance(init, str):
        if init == "occupied":
            m = np.ones(K, np.uint8)
        elif init == "free":
            m = np.zeros(K, np.uint8)
        elif init == "random":
            m = (np.random.default_rng(seed).random(K) < 0.5).astype(np.uint8)
        else:
            raise ValueError(f"init must be 'occupied', 'free', 'random' or a map, got {init!r}")
    else:
        m = as_binary_maps(init, K, "init map", flatten=True).numpy().astype(np.uint8)
    m[model.known_free.numpy()] = 0
    return m


def map_estimate(model: OccupancyModel, init="occupied", max_sweeps: int = 100, seed: int = 0) -> MapEstimate:
    """Hill-climb to a local maximum of ``log p(m, z)`` (not always the global one: module docstring).

    Args:
        model: the model; priors with a compiled face (``prior.compiled()``: independent cells, MRF /
            stencil / table priors) run in compiled kernels; others through the prior's ``log_prob_patch``
            one cell at a time (small maps).
        init: ``"occupied"`` (thesis), ``"free"``, ``"random"`` (seeded) or a ``K`` map.
        max_sweeps: stop after this many sweeps even if cells still change.
    """
    m = _initial(model, init, seed)
    st = cs.cell_state_of(m, model.ray_index())
    order = model.latent.numpy().astype(np.int64)
    prior = model.prior.compiled()
    if prior is not None:
        sweeps = cs.icm_sweeps(st, order, prior, int(max_sweeps))
    else:
        sweeps = _generic_icm(model, st, order, int(max_sweeps))
    m = st.m
    mt = torch.from_numpy(m.astype(np.float64))
    lj = float(model.log_joint(mt))
    return MapEstimate(mt, lj, int(sweeps), bool(sweeps < max_sweeps))


def _generic_icm(model, st, order, max_sweeps) -> int:
    """ICM for priors without a compiled face: the prior's patch conditional, cell by cell."""
    m = st.m
    configs = torch.tensor([[0.0], [1.0]], dtype=torch.float64)
    for s in range(max_sweeps):
        changed = 0
        for k in order:
            cur = torch.from_numpy(m.astype(np.float64))
            lp = model.prior.log_prob_patch(cur, torch.tensor([int(k)]), configs)
            lik = cs.log_lik_ratio(st, int(k))
            lo = float(lp[1] - lp[0]) + lik if torch.isfinite(lp).all() else (np.inf if lp[1] > lp[0] else -np.inf)
            v = 1 if lo > 0 else 0 if lo < 0 else int(m[k])
            if v != m[k]:
                cs.set_cell(st, int(k), v)
                changed += 1
        if changed == 0:
            return s + 1
    return max_sweeps
