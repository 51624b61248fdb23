r"""The growing ray store of an online map: the chain's state with spare capacity
(:class:`~ogm_ppl.inference._kernels.online.OnlineState`), the likelihood rows of new rays, the ray side
appended (doubled when full), the caps of the fixed-point scale, and the focus region of new rays.

**Fixed-point scale.** The kept sums are integers in units of ``2^-S``; with caps ``n_cap >= max_k n_k``
(the rays through a cell) and ``b_cap >= max |ll|``, ``S = min(60, floor(62 - log2(n_cap (2 b_cap + 1) +
1)))`` (:func:`_bits_for`, the offline rule at the caps), so no sum can overflow while the caps hold;
:func:`scale_caps` doubles a cap that new rays exceed.
"""

from __future__ import annotations

import math

import numpy as np
import torch

from ogm_ppl.grid import Grid
from ogm_ppl.inference._kernels import cell_sweep as cs
from ogm_ppl.inference._kernels import online as ok
from ogm_ppl.models.occupancy import OccupancyModel
from ogm_ppl.raycast import Rays
from ogm_ppl.sensors import SensorModel


def _grow(a: np.ndarray, n: int) -> np.ndarray:
    """``a`` with room for at least ``n`` items along axis 0 (capacity doubled; the new room is not
    initialised: only the live part is ever read)."""
    if a.shape[0] >= n:
        return a
    cap = max(n, 2 * a.shape[0], 16)
    out = np.empty((cap,) + a.shape[1:], a.dtype)
    out[: a.shape[0]] = a
    return out


def _bits_for(n_cap: int, b_cap: float) -> int:
    bound = n_cap * (2.0 * b_cap + 1.0) + 1.0
    return min(60, math.floor(62 - math.log2(bound)))


class _Outside:
    """What the likelihood rows read of the prior: its size and ``lambda_out`` (computed once)."""

    def __init__(self, prior) -> None:
        self.num_cells = prior.num_cells
        self._lam = float(prior.outside_occupancy())

    def outside_occupancy(self) -> float:
        return self._lam


def _ragged_cols(lengths: np.ndarray) -> np.ndarray:
    """``0..len_r`` for every ray, concatenated."""
    n = lengths + 1
    return np.arange(int(n.sum())) - np.repeat(np.cumsum(n) - n, n)


def empty_state(m: np.ndarray, bits: int) -> ok.OnlineState:
    """The state of a chain at the map ``m`` (``K`` uint8) that holds no ray yet, at ``bits`` fraction bits."""
    K = m.shape[0]
    return ok.OnlineState(
        m,
        np.zeros(16, cs.RAY),
        np.zeros(K, np.int64),
        np.zeros(K, cs.INF),
        False,
        np.zeros(17, np.int64),
        np.zeros(16, np.int64),
        np.zeros(K, np.int64),
        np.zeros(K, np.int64),
        np.zeros(K, np.int64),
        np.zeros(1024, np.int32),
        np.zeros(1024, np.int32),
        np.zeros(32, np.float64),
        float(2.0**bits),
    )


def likelihood_rows(grid: Grid, rays: Rays, sensor: SensorModel, outside: _Outside) -> tuple[np.ndarray, float]:
    """The likelihood rows ``log p(z_r | f)``, ``f = 0..len_r``, of ``rays`` alone, concatenated (ragged), and
    their largest finite ``|entry|``. Raises ``ValueError`` on NaN or ``+inf`` entries."""
    # by the offline model's code (known_free=None: no pinning here); one torch thread: on tables of a
    # scan's size, more threads cost more than they save
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        table = OccupancyModel(grid, rays, sensor, outside, known_free=None).loglik_table.numpy()
    finally:
        torch.set_num_threads(threads)
    lengths = rays.lengths
    ragged = table[np.repeat(np.arange(rays.num_rays), lengths + 1), _ragged_cols(lengths)]
    bad = np.isnan(ragged) | (ragged == np.inf)
    if bad.any():
        raise ValueError("the sensor model gave NaN / +inf log-likelihoods for the new rays")
    finite = ragged[np.isfinite(ragged)]
    big = float(np.abs(finite).max()) if finite.size else 0.0
    return ragged, big


def append_rays(
    st: ok.OnlineState, rays: Rays, ragged: np.ndarray, R0: int, e0: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The ray side of ``st`` (rays ``0..R0-1`` and ``e0`` ray-cell entries live) with ``rays`` and their rows
    ``ragged`` appended, each array grown by doubling where full: ``(offsets, cells, ll, hit records)``; the
    new rays' hit records are not set. An array with room is written past its live part only."""
    R1, e1 = R0 + rays.num_rays, e0 + rays.nnz
    offsets = _grow(st.offsets, R1 + 1)
    offsets[R0 + 1 : R1 + 1] = e0 + rays.offsets[1:]
    cells = _grow(st.cells, e1)
    cells[e0:e1] = rays.cells
    ll = _grow(st.ll, e1 + R1)
    ll[e0 + R0 : e1 + R1] = ragged
    rec = _grow(st.rays, R1)
    return offsets, cells, ll, rec


def scale_caps(n_max: int, big: float, n_cap: int, b_cap: float) -> tuple[int, float, int]:
    """The caps ``(n_cap, b_cap)`` once up to ``n_max`` rays pass through a cell and entries reach ``|big|``
    (each doubled until it holds), and the fraction bits ``S`` they leave. Raises ``ValueError`` when that
    is fewer than ``MIN_BITS``."""
    while n_max > n_cap:
        n_cap *= 2
    if big > b_cap:
        b_cap = max(2.0 * big, 2.0 * b_cap, 1.0)
    bits = _bits_for(n_cap, b_cap)
    if bits < cs.MIN_BITS:
        raise ValueError(
            f"likelihood entries up to |{b_cap:.3g}| over up to {n_cap} rays a cell leave "
            f"{bits} fraction bits for the fixed-point sums (need {cs.MIN_BITS})"
        )
    return n_cap, b_cap, bits


def focus_region(st: ok.OnlineState, rays: Rays, R0: int, R1: int, margin: int, pinned: np.ndarray) -> np.ndarray:
    """The focus region of the new rays ``R0..R1-1`` of ``st`` (``rays``): the cells where they end and their
    first and second hits, dilated by ``margin`` cells (Chebyshev), less the ``pinned`` cells; sorted."""
    lengths = rays.lengths
    touched = np.zeros(rays.grid.num_cells, bool)
    touched[rays.endpoint_cells()] = True
    ends = st.offsets[R0:R1] + np.minimum(st.rays["f"][R0:R1], lengths - 1)
    touched[st.cells[ends]] = True
    ends = st.offsets[R0:R1] + np.minimum(st.rays["s"][R0:R1], lengths - 1)
    touched[st.cells[ends]] = True
    g = rays.grid
    rows, cols = (1, g.num_cells) if g.ndim == 1 else g.shape
    region = ok.dilate(touched, rows, cols, margin)
    return np.ascontiguousarray(region[~pinned[region]], dtype=np.int64)


def ray_fields(rays: Rays, readings: int) -> dict[str, np.ndarray]:
    """The fields of ``rays`` (from :func:`~ogm_ppl.raycast.raycast`) that a model of all the scans needs,
    their readings numbered after the ``readings`` held before."""
    assert rays.reading is not None and rays.range_len is not None and rays.geometry is not None  # raycast fills them
    return {
        "t_enter": rays.t_enter,
        "z": rays.z,
        "is_max": rays.is_max,
        "endpoint_in_grid": rays.endpoint_in_grid,
        "range_cells": rays.range_cells,
        "reading": rays.reading + readings,
        "range_len": rays.range_len,
        "geometry": rays.geometry,
    }
