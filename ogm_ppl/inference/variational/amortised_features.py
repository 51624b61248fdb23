r"""Features of the evidence: the readings rasterised per cell, the input ``x(z)`` of the amortised guide's
network (:mod:`~ogm_ppl.inference.variational.amortised_net`).

Cell ``k`` of ``x(z)`` holds its pass-through and hit counts, the hit share, the evidence grid of Section
2.4/2.5 with a fitted update term (by default p21),

.. math:: l_k = \sum_n \Delta(\kappa_{n,k};\ z_n),

the observed and pinned masks, an all-ones channel (the zero padding of the convolutions then marks the grid
edge) and the tile phase ``(row mod h, col mod w)`` of a patch prior (Section 5.2.2).
"""

from __future__ import annotations

from functools import lru_cache

import torch

from ogm_ppl.models.occupancy import OccupancyModel
from ogm_ppl.raycast import Rays

__all__ = ["FEATURE_VERSION", "base_channels", "evidence_features", "feature_names", "phase_channels", "ray_terms"]

#: feature set of :func:`evidence_features` (bumped when a channel changes meaning)
FEATURE_VERSION = 1
_BASE_FEATURES = ("pass_count", "hit_count", "hit_share", "log_odds", "observed", "pinned", "inside")
_LOGODDS_CLIP = 12.0


@lru_cache(maxsize=8)
def _delta(name: str):
    from ogm_ppl.models.delta import delta_by_name

    d = delta_by_name(name)
    if d is None:
        raise ValueError(f"unknown Delta {name!r} for the log-odds feature")
    return d


_TABLE_CACHE_ENTRIES = 1 << 20  # tables up to 8 MiB are kept (a few of them): a replay's scans share a few sizes


@lru_cache(maxsize=4)
def _cached_table(name: str, n_kappa: int, n_z: int) -> torch.Tensor:
    with torch.no_grad():
        return _delta(name).table(n_kappa, n_z).to(torch.float64)


def _delta_table(name: str, n_kappa: int, n_z: int) -> torch.Tensor:
    """``Delta``'s ``n_kappa x (n_z + 1)`` float64 table (column ``n_z``: max-range readings); small tables are
    kept, so that scans added one at a time do not rebuild the same table (the same computation: the same
    values). Read only."""
    if n_kappa * (n_z + 1) <= _TABLE_CACHE_ENTRIES:
        return _cached_table(name, n_kappa, n_z)
    with torch.no_grad():
        return _delta(name).table(n_kappa, n_z).to(torch.float64)


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
    passed, hit, lo_terms = ray_terms(r, model.range_to_kappa(z), is_max, delta)  # B x nnz
    cells = torch.from_numpy(r.cells)
    n_pass = torch.zeros(B, K, dtype=torch.float64).index_add_(1, cells, passed)
    n_hit = torch.zeros(B, K, dtype=torch.float64).index_add_(1, cells, hit)
    lo = torch.zeros(B, K, dtype=torch.float64).index_add_(1, cells, lo_terms)
    chans = base_channels(n_pass, n_hit, lo, model.known_free.to(torch.float64).expand(B, K))
    g = model.grid
    rows, cols = (g.rows, g.cols) if g.ndim == 2 else (1, g.num_cells)
    x = torch.stack(chans, 1).reshape(B, len(chans), rows, cols)
    ph = phase_channels(rows, cols, phase)
    if ph is not None:
        x = torch.cat([x, ph[None].expand(B, -1, -1, -1)], 1)
    return x.to(torch.float32).reshape(*batch, x.shape[1], rows, cols)


def ray_terms(
    rays: Rays, kz: torch.Tensor, is_max: torch.Tensor, delta: str
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    r"""What each ray-cell entry adds to its cell's counts and evidence: ``(passed, hit, lo)``, each
    ``B x nnz`` float64, for readings of kappa ``kz`` (``B x R``) and max-range flags ``is_max`` (``B x R``).
    ``passed``: the entry lies before its reading (or on a max-range ray); ``hit``: it holds the reading;
    ``lo``: ``Delta(kappa, z)`` of the update term ``delta`` (Eq. 2.10). Each entry's terms depend on its
    own ray only, so the terms of rays cast apart are those of the same rays cast together."""
    ray = torch.from_numpy(rays.ray_of_entry)
    kap = torch.from_numpy(rays.kappa)
    kze, mx = kz[:, ray], is_max[:, ray]  # B x nnz
    passed = ((kap[None] < kze) | mx).to(torch.float64)
    hit = ((kap[None] == kze) & ~mx).to(torch.float64)
    # the evidence grid, as ogm_ppl.inference.log_odds.evidence_grid builds it (delta_table_for)
    n_kappa = int(rays.lengths.max())
    hz = kz[~is_max]
    n_z = max(int(hz.max()) + 1 if hz.numel() else 0, n_kappa)
    table = _delta_table(delta, n_kappa, n_z)
    col = torch.where(mx, n_z, kze)
    return passed, hit, table[kap[None].expand_as(col), col]


def base_channels(
    n_pass: torch.Tensor, n_hit: torch.Tensor, lo: torch.Tensor, pinned: torch.Tensor
) -> list[torch.Tensor]:
    """The 7 channels of :data:`_BASE_FEATURES` (float64, each of the inputs' shape) from a cell's pass and hit
    counts, its evidence ``l_k`` and its pinned flag (float64 0/1): elementwise, so any subset of cells gets the
    values the whole grid gets (to the last bit where torch's vectorised and scalar ``log1p`` agree)."""
    seen = (n_pass + n_hit) > 0
    share = torch.where(seen, n_hit / (n_hit + n_pass).clamp(min=1), 0.0)
    return [
        torch.log1p(n_pass),
        torch.log1p(n_hit),
        share,
        lo.clamp(-_LOGODDS_CLIP, _LOGODDS_CLIP) / 4,
        seen.to(torch.float64),
        pinned,
        torch.ones_like(n_pass),
    ]


def phase_channels(rows: int, cols: int, phase: tuple[int, int]) -> torch.Tensor | None:
    """The tile phase one-hot ``(row mod h, col mod w)``: ``(h + w) x rows x cols`` float64 (``None`` for
    ``phase = (0, 0)``)."""
    h, w = (int(v) for v in phase)
    if not (h and w):
        return None
    ri = torch.arange(rows) % h
    ci = torch.arange(cols) % w
    oh_r = (ri[None, :, None] == torch.arange(h)[:, None, None]).expand(h, rows, cols)
    oh_c = (ci[None, None, :] == torch.arange(w)[:, None, None]).expand(w, rows, cols)
    return torch.cat([oh_r, oh_c]).to(torch.float64)
