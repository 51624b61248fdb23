"""Fingerprints of what a checkpoint belongs to: model, kernel and tracked statistics.

A Gibbs checkpoint resumed under anything else would silently mix two posteriors, so :func:`run_gibbs`
stores one short hash per component and refuses a checkpoint whose hashes differ, naming the component:

* ``grid``: shape, resolution, origin;
* ``readings``: the rays (cells, readings in kappa and in range, max-range flags) and the pinned cells;
* ``sensor``: the per-ray log-likelihood table (it depends on the sensor model and its parameters);
* ``prior``: the prior's type and its ``log_prob`` of eight seeded random maps (a functional fingerprint:
  it sees any parameter that changes the prior, whatever the prior stores);
* ``kernel``: the kernel's type and its public settings (scan order, patch shape, initialisation, ...);
* ``stats``: the tracked rays, pairs, paths and traced cells.
"""

from __future__ import annotations

import hashlib

import numpy as np
import torch

__all__ = ["digest", "fingerprint"]


def digest(*parts) -> str:
    """A short sha256 of ``parts`` (arrays by dtype, shape and bytes; anything else by ``repr``)."""
    h = hashlib.sha256()
    for p in parts:
        if isinstance(p, torch.Tensor):
            p = p.detach().cpu().numpy()
        if isinstance(p, np.ndarray):
            h.update(str((p.dtype.str, p.shape)).encode())
            h.update(np.ascontiguousarray(p).tobytes())
        else:
            h.update(repr(p).encode())
        h.update(b"|")
    return h.hexdigest()[:16]


def _priordigest(prior, num_cells: int) -> str:
    g = torch.Generator().manual_seed(12345)
    maps = (torch.rand(8, num_cells, generator=g, dtype=torch.float64) < 0.3).to(torch.float64)
    with torch.no_grad():
        lp = torch.as_tensor(prior.log_prob(maps), dtype=torch.float64)
    lp = torch.where(torch.isfinite(lp), torch.round(lp * 1e6) / 1e6, lp)
    return digest(type(prior).__qualname__, lp)


def _settings(kernel) -> dict:
    """A :class:`~ogm_ppl.inference.mcmc.kernel.MapKernel`'s ``settings()``; for another kernel its public
    attributes of simple types."""
    if hasattr(kernel, "settings"):
        return kernel.settings()
    return {
        k: v
        for k, v in sorted(vars(kernel).items())
        if not k.startswith("_")
        and k not in ("model", "sweeps", "transforms")
        and isinstance(v, (bool, int, float, str, tuple, type(None)))
    }


def fingerprint(kernel, stats) -> dict[str, str]:
    """One hash per component (module docstring) of a kernel's model, the kernel and the statistics."""
    model = kernel.model
    g, r = model.grid, model.rays
    return {
        "grid": digest(g.shape, g.resolution, tuple(np.asarray(g.origin).tolist())),
        "readings": digest(r.offsets, r.cells, r.z, r.is_max, r.range_cells, model.known_free),
        "sensor": digest(repr(model.sensor), model.loglik_table),
        "prior": _priordigest(model.prior, model.num_cells),
        "kernel": digest(type(kernel).__qualname__, _settings(kernel)),
        "stats": digest(stats.rays, stats.pairs, [p.numpy() for p in stats.paths], stats.trace_cells),
    }
