"""What an online map refuses: options that make no chain (and the tile-table priors it warns about), and
scans that do not fit the map (another sensor model, grid, maximum range or beam count; no reading).
"""

from __future__ import annotations

import warnings

import numpy as np
import torch

from ogm_ppl.grid import Grid
from ogm_ppl.inference._kernels import cell_sweep as cs
from ogm_ppl.models.occupancy import check_prior_fits
from ogm_ppl.scans import Scans
from ogm_ppl.sensors import SensorModel

_UPDATES = {"gibbs": cs.HEAT_BATH, "metropolised": cs.METROPOLISED}


class TilePriorWarning(UserWarning):
    """A tile-table prior (a compiled bundle with ``sparse_patches()``) given to :class:`OnlineMap`, whose
    single-cell updates leave such a chain all but frozen."""


def check_options(
    grid: Grid,
    sensor: SensorModel,
    prior,
    kernel: str,
    update: str,
    sweeps_per_scan: int,
    full_every: int,
    margin: int,
    init_new: str,
    initial_rays_per_cell: int,
):
    """Check the options of :class:`~ogm_ppl.inference.online.OnlineMap` (raising ``ValueError`` / ``TypeError``; a
    :class:`TilePriorWarning` for a tile-table prior). Returns the prior's compiled face."""
    if kernel != "cell":
        raise ValueError(f"OnlineMap supports kernel='cell' (single-cell updates), got {kernel!r}")
    if update not in _UPDATES:
        raise ValueError(f"update must be one of {tuple(_UPDATES)}, got {update!r}")
    if not isinstance(grid, Grid):
        raise TypeError(f"grid must be an ogm_ppl.Grid (cells, resolution, origin), got {type(grid).__name__}")
    if not isinstance(sensor, SensorModel):
        raise TypeError(f"sensor must be a SensorModel, got {type(sensor).__name__}")
    if not hasattr(prior, "num_cells"):
        raise TypeError(f"prior must be a MapPrior, got {type(prior).__name__}")
    check_prior_fits(grid, prior)
    compiled = prior.compiled()
    if compiled is None:
        raise ValueError(
            f"OnlineMap needs a prior with a compiled face (prior.compiled()); {type(prior).__name__} has none"
        )
    if compiled.sparse_patches():
        warnings.warn(
            TilePriorWarning(
                f"OnlineMap updates single cells, and under the tile-table prior {type(prior).__name__} a "
                "single cell can rarely change without making its tile one the table never counted: the chain "
                "is exact but barely moves. Map with patch Gibbs over the prior's tiles instead "
                "(ogm_ppl.exploration.active.RebuildMapper, which explore() uses for such priors)"
            ),
            stacklevel=3,
        )
    for name, v in (("sweeps_per_scan", sweeps_per_scan), ("full_every", full_every), ("margin", margin)):
        if int(v) != v or v < 0:
            raise ValueError(f"{name} must be a non-negative integer, got {v!r}")
    if init_new not in ("keep", "hits", "ogm"):
        raise ValueError(f"init_new must be 'keep', 'hits' or 'ogm', got {init_new!r}")
    if initial_rays_per_cell < 1:
        raise ValueError(f"initial_rays_per_cell must be positive, got {initial_rays_per_cell}")
    return compiled


def start_map(init, K: int) -> np.ndarray:
    """The starting map of ``K`` cells (uint8): ``"free"`` or a ``K`` 0/1 map, checked."""
    if isinstance(init, str):
        if init != "free":
            raise ValueError(f"init must be 'free' or a map of {K} cells, got {init!r}")
        m = np.zeros(K, np.uint8)
    else:
        a = np.asarray(torch.as_tensor(init).detach().cpu()).ravel()
        if a.shape != (K,) or not np.isin(a, (0, 1)).all():
            raise ValueError(f"init map must hold {K} values 0/1, got shape {np.shape(init)}")
        m = a.astype(np.uint8)
    return m


def check_scans(
    scans: Scans,
    sensor: SensorModel | None,
    grid: Grid | None,
    map_sensor: SensorModel,
    map_grid: Grid,
    max_range: float | None,
    beams: int | None,
) -> None:
    """Check that ``scans`` (taken with ``sensor`` on ``grid``, where the caller says) fit a map of
    ``map_sensor`` on ``map_grid`` holding scans of ``max_range`` and ``beams`` (``None``: none yet)."""
    if not isinstance(scans, Scans):
        raise TypeError(f"add_scans takes Scans, got {type(scans).__name__}")
    if sensor is not None and not _same_sensor(sensor, map_sensor):
        raise ValueError(f"scans taken with another sensor model ({sensor!r}) than the map's ({map_sensor!r})")
    if grid is not None and grid != map_grid:
        raise ValueError(f"scans meant for another grid ({grid}) than the map's ({map_grid})")
    if scans.num_scans == 0 or scans.num_valid == 0:
        raise ValueError(
            f"add_scans got {scans.num_scans} scans with no reading (every beam invalid or none): nothing to add"
        )
    if max_range is not None and scans.max_range != max_range:
        raise ValueError(
            f"scans of maximum range {scans.max_range} m added to a map whose sensor has {max_range} m "
            "(another sensor model)"
        )
    if beams is not None and scans.beams_per_scan != beams:
        raise ValueError(f"scans of {scans.beams_per_scan} beams added to a map of {beams}-beam scans (another sensor)")


def _same_sensor(a: SensorModel, b: SensorModel) -> bool:
    if a is b:
        return True
    if type(a) is not type(b):
        return False
    va, vb = vars(a), vars(b)
    if va.keys() != vb.keys():
        return False
    for k in va:
        x, y = va[k], vb[k]
        if isinstance(x, (torch.Tensor, np.ndarray)) or isinstance(y, (torch.Tensor, np.ndarray)):
            if not torch.equal(torch.as_tensor(x), torch.as_tensor(y)):
                return False
        elif x != y:
            return False
    return True
