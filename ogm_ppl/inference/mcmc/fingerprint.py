"""Fingerprints of what a checkpoint belongs to: model, kernel and tracked statistics.

A Gibbs checkpoint resumed under anything else would silently mix two posteriors, so :func:`run_gibbs`
stores one short hash per component and refuses a checkpoint whose hashes differ, naming the component:

* ``grid``: shape, resolution, origin;
* ``readings``: the rays (cells, readings in kappa and in range, max-range flags) and the pinned cells;
* ``sensor``: the per-ray log-likelihood table (it depends on the sensor model and its parameters);
* ``prior``: the prior's type, the arrays of its compiled bundle (the tables themselves: two table priors of
  one kind built from different corpora differ there even where every test map scores ``-inf``), the arrays
  and plain settings the prior holds, and its ``log_prob`` of seeded random maps of several densities (a
  functional fingerprint for priors that keep their parameters elsewhere);
* ``kernel``: the kernel's type and its public settings (scan order, patch shape, initialisation, ...);
* ``stats``: the tracked rays, pairs, paths and traced cells.
"""

from __future__ import annotations

import hashlib
import math

import numpy as np
import torch

__all__ = ["digest", "fingerprint", "prior_digest", "prior_name_digest"]


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


def _simple(v) -> bool:
    """Values whose ``repr`` is the same in every process (no object addresses)."""
    if isinstance(v, bool | int | float | str | type(None) | np.generic):
        return True
    return isinstance(v, tuple) and all(_simple(x) for x in v)


def _tables(obj) -> list:
    """The arrays and plain settings ``obj`` holds: every NamedTuple field, or the public attributes by
    sorted name (private ones may be caches filled later, which must not change the digest); a bundle's
    ``cache_fields()`` (memos its sweeps fill, as the net field's) count as empty: zeros of their shape."""
    if hasattr(obj, "_asdict"):
        cache = set(obj.cache_fields()) if hasattr(obj, "cache_fields") else set()
        items = [(k, np.zeros_like(v) if k in cache else v) for k, v in obj._asdict().items()]
    else:
        items = [(k, v) for k, v in sorted(vars(obj).items()) if not k.startswith("_")]
    out: list = []
    for k, v in items:
        if isinstance(v, np.ndarray | torch.Tensor) or _simple(v):
            out += [k, v]
    return out


def prior_digest(prior, num_cells: int) -> str:
    """The prior's type, its compiled bundle's tables (every array: the patch tables, stencil weights,
    border segments), the arrays and plain settings it holds, and its ``log_prob`` of seeded maps at
    densities 0, 0.05, 0.3, 0.6 and 1 (for priors whose state is neither)."""
    parts: list = [type(prior).__qualname__]
    bundle = prior.compiled() if hasattr(prior, "compiled") else None
    if bundle is not None:
        parts += [type(bundle).__qualname__, *_tables(bundle)]
    parts += _tables(prior)
    g = torch.Generator().manual_seed(12345)
    u = torch.rand(8, num_cells, generator=g, dtype=torch.float64)
    maps = torch.cat([(u < q).to(torch.float64) for q in (0.0, 0.05, 0.3, 0.6, 1.0001)])
    with torch.no_grad():
        lp = torch.as_tensor(prior.log_prob(maps), dtype=torch.float64)
    lp = torch.where(torch.isfinite(lp), torch.round(lp * 1e6) / 1e6, lp)
    return digest(*parts, lp)


def prior_name_digest(name: str) -> str:
    """:func:`prior_digest` of the prior ``name`` (:func:`~ogm_ppl.priors.named.prior_by_name`) built on an
    8 x 8 grid, or on 8 cells for a 1D-only kind: what the name stands for now (tables counted anew, refitted
    weights or exponents, a registered kind edited give another digest). What a result computed under the name
    records, so that a rerun after the prior changed recomputes it. ``ValueError`` (both grids' problems) when
    it builds on neither."""
    from ogm_ppl.priors import prior_by_name

    problems: list[str] = []
    for shape in ((8, 8), (8,)):
        try:
            return prior_digest(prior_by_name(name, shape), math.prod(shape))
        except Exception as e:  # a 2D-only or 1D-only kind, or one built for other grids only
            problems.append(f"{type(e).__name__}: {e}")
    if problems[0] == problems[1]:  # the name itself is wrong (an unknown kind, unreadable tables)
        raise ValueError(problems[0].partition(": ")[2])
    raise ValueError(f"prior {name!r} builds on neither an 8 x 8 grid nor 8 cells ({'; '.join(problems)})")


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
        "prior": prior_digest(model.prior, model.num_cells),
        "kernel": digest(type(kernel).__qualname__, _settings(kernel)),
        "stats": digest(stats.rays, stats.pairs, [p.numpy() for p in stats.paths], stats.trace_cells),
    }
