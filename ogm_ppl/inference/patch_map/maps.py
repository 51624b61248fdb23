r"""Patch maps (Chapter 3): the map split into patches of ``L`` cells, each holding a distribution over its
``W = 2^L`` configurations.

* :func:`online_patch_map` (Section 3.1): every reading updates every patch it crosses, independently of
  the other patches, with the forward sensor model (Eq. 3.1; cells outside the patch marginalised under the
  cell prior) or with the patch inverse sensor model (Eq. 3.2).
* :func:`offline_patch_map` (Section 3.2, Eq. 3.3-3.4): each patch's configurations are weighed by all
  readings through it with every cell outside the patch taken from a reference map (the MAP map by
  default, or e.g. the ground truth); cells no reading reaches count as occupied in the reference. With
  ``overlap=True`` a patch is centred on every cell and only its centre marginal is kept.

Marginals (Eq. 3.4) and, for non-overlapping patches, ``p(f | z)`` along a ray as a product across
patches (the Eq. 4.7 analogue) come with the result. All patch work runs in compiled kernels.

A note on Eq. 3.1. "The first occupied cell is independent of cells outside the patch" could be read as
"outside cells are free", but then a reading far beyond the patch has zero (Gaussian) likelihood under the
all-free configuration and drives every patch it crosses to "occupied"; we marginalise the outside cells
under the prior instead, which makes ``L = 1`` exactly Elfes's update (tested).
"""

from __future__ import annotations

import math
from functools import cached_property

import numpy as np
import torch

from ogm_ppl._validate import as_binary_maps
from ogm_ppl.inference._kernels.cells import first_hits
from ogm_ppl.inference._kernels.patch_state import patch_state
from ogm_ppl.inference._kernels.patches import INVERSE, OFFLINE, ONLINE, PatchSensor, patch_map_all
from ogm_ppl.inference.tiling import centred_patches, tile_patches
from ogm_ppl.models.occupancy import OccupancyModel
from ogm_ppl.posterior import MapPosterior
from ogm_ppl.progress import Progress, progress_over

__all__ = ["PatchMap", "online_patch_map", "offline_patch_map"]


class PatchMap(MapPosterior):
    """Result of a patch map: marginals, the patches and (non-overlapping) their configuration weights."""

    def __init__(self, model, patches: np.ndarray, marginals: torch.Tensor, log_weights: np.ndarray | None, kind: str):
        self.model = model
        self.patches = patches
        self._marginals = marginals
        self.log_weights = log_weights
        self.kind = kind

    @property
    def marginals(self) -> torch.Tensor:
        return self._marginals

    def pair_joint(self, cells=None):  # pragma: no cover - not defined across patches
        raise NotImplementedError("a patch map keeps correlations within patches only; use first_hit or marginals")

    @cached_property
    def _where(self) -> dict:
        out = {}
        for p, row in enumerate(self.patches):
            bit = 0
            for c in row:
                if c >= 0:
                    out[int(c)] = (p, bit)
                    bit += 1
        return out

    def first_hit(self, ray: int = 0) -> torch.Tensor:
        """``p(f = kappa | z)`` along ``ray`` with patches independent and cells within a patch correlated."""
        if self.log_weights is None:
            raise ValueError("p(f | z) needs non-overlapping patches (the overlapping map keeps centre marginals only)")
        cells = self.model.rays.ray(ray)
        n = len(cells)
        probs = np.exp(self.log_weights)
        W = probs.shape[1]
        bits = (np.arange(W)[:, None] >> np.arange(16)) & 1
        out = np.zeros(n + 1)
        for k in range(n + 1):
            # required value of each ray cell up to k: free before k, occupied at k
            need = {}
            for j in range(min(k + 1, n)):
                need[int(cells[j])] = 1 if j == k else 0
            p = 1.0
            by_patch: dict[int, list[tuple[int, int]]] = {}
            for c, v in need.items():
                if c in self._where:
                    pi, b = self._where[c]
                    by_patch.setdefault(pi, []).append((b, v))
                elif v == 1:
                    p = 0.0  # a pinned (free) cell cannot be the first occupied one
            for pi, req in by_patch.items():
                mask = np.ones(W, dtype=bool)
                for b, v in req:
                    mask &= bits[:, b] == v
                p *= probs[pi][mask].sum()
            out[k] = p
        return torch.from_numpy(out)

    def prob_free(self, cells) -> float:
        if self.log_weights is None:
            raise ValueError("prob_free needs non-overlapping patches")
        probs = np.exp(self.log_weights)
        W = probs.shape[1]
        bits = (np.arange(W)[:, None] >> np.arange(16)) & 1
        by_patch: dict[int, list[int]] = {}
        for c in np.asarray(cells).ravel().tolist():
            if c in self._where:
                pi, b = self._where[c]
                by_patch.setdefault(pi, []).append(b)
        p = 1.0
        for pi, bs in by_patch.items():
            mask = np.ones(W, dtype=bool)
            for b in bs:
                mask &= bits[:, b] == 0
            p *= probs[pi][mask].sum()
        return float(p)


#: patch configurations weighed between two progress updates (about a second of work)
_CONFIGURATIONS_PER_STEP = 1 << 21


def _run(model, mode, patches, centre, m_ref, keep, log_match=0.0, log_other=0.0, progress: bool | Progress = False):
    prior = model.prior.compiled()
    lo = model.prior.cell_log_odds()
    if lo is None or prior is None:
        raise ValueError("patch maps need a prior with independent cells (a uniform patch prior is lambda = 0.5)")
    if patches.shape[1] > 16:
        raise ValueError(f"patches of {patches.shape[1]} cells: at most 16 (2^16 configurations)")
    lam = torch.where(model.known_free, 0.0, torch.sigmoid(lo)).numpy()
    with np.errstate(divide="ignore"):
        log_on, log_off = np.log(lam), np.log1p(-lam)
    r = model.rays
    index = model.ray_index()
    ps = patch_state(m_ref, first_hits(m_ref, index.offsets, index.cells), index)
    sensor = PatchSensor(log_on, log_off, r.z, r.is_max, float(log_match), float(log_other))
    patches = np.ascontiguousarray(patches)
    P, L = patches.shape
    step = max(1, _CONFIGURATIONS_PER_STEP >> L)  # patches are weighed independently: in blocks, with progress
    margs, weight_blocks = [], []
    with progress_over(progress, P, f"patch map ({L}-cell patches)", unit="patch") as bar:
        for a in range(0, P, step):
            m, w = patch_map_all(mode, patches[a : a + step], centre, ps, prior, sensor, keep)
            margs.append(m)
            weight_blocks.append(w)
            bar.update(min(step, P - a))
    marg = np.concatenate(margs) if margs else np.zeros((0, L))
    weights = np.concatenate(weight_blocks) if weight_blocks else np.zeros((0, 1 << L))
    out = torch.zeros(model.num_cells, dtype=torch.float64)
    cols = range(patches.shape[1]) if centre < 0 else [centre]
    for j in cols:
        ok = patches[:, j] >= 0
        out[torch.from_numpy(patches[ok, j])] = torch.from_numpy(marg[ok, j])
    return out.clamp(0.0, 1.0), (weights if keep else None)  # sums of exp may pass 1 by an ulp


def online_patch_map(
    model: OccupancyModel,
    patch=3,
    offset=0,
    sensor: str = "forward",
    p_match: float = 0.9,
    progress: bool | Progress = False,
) -> PatchMap:
    """The online patch map (Section 3.1) with non-overlapping patches.

    Args:
        sensor: ``"forward"`` (Eq. 3.1) or ``"inverse"`` (Eq. 3.2 with ``p_match``).
        progress: show progress over the patches (:func:`~ogm_ppl.progress.progress_over`: a bar on a
            terminal, plain lines with the time left once past 10 s), or a caller's own ``Progress``.
    """
    patches = tile_patches(model, patch, offset)
    m_dummy = np.zeros(model.num_cells, np.uint8)
    if sensor == "forward":
        marg, w = _run(model, ONLINE, patches, -1, m_dummy, True, progress=progress)
    elif sensor == "inverse":
        if not 0.0 < p_match < 1.0:
            raise ValueError(f"p_match must lie in (0, 1), got {p_match}")
        marg, w = _run(
            model, INVERSE, patches, -1, m_dummy, True, math.log(p_match), math.log1p(-p_match), progress=progress
        )
    else:
        raise ValueError(f"sensor must be 'forward' or 'inverse', got {sensor!r}")
    return PatchMap(model, patches, marg, w, f"online-{sensor}")


def reference_map(model: OccupancyModel, reference="map") -> np.ndarray:
    """The reference of the offline patch map: the MAP map (``"map"``) or a given map; cells no reading
    reaches count as occupied (Section 3.2)."""
    if isinstance(reference, str):
        if reference != "map":
            raise ValueError(f"reference must be 'map' or a map, got {reference!r}")
        from ogm_ppl.inference.exact.map_estimate import map_estimate

        ref = map_estimate(model, init="occupied").map.numpy()
    else:
        ref = as_binary_maps(reference, model.num_cells, "reference map", flatten=True).numpy()
    m = (ref != 0).astype(np.uint8)
    m[~model.rays.reached()] = 1
    m[model.known_free.numpy()] = 0
    return m


def offline_patch_map(
    model: OccupancyModel,
    patch=3,
    offset=0,
    reference="map",
    overlap: bool = False,
    progress: bool | Progress = False,
) -> PatchMap:
    """The offline patch map (Section 3.2): non-overlapping, or a patch centred on every cell (``overlap``);
    ``progress`` as in :func:`online_patch_map`."""
    m_ref = reference_map(model, reference)
    if overlap:
        patches, centre = centred_patches(model, patch)
        marg, _ = _run(model, OFFLINE, patches, centre, m_ref, False, progress=progress)
        return PatchMap(model, patches, marg, None, "offline-overlap")
    patches = tile_patches(model, patch, offset)
    marg, w = _run(model, OFFLINE, patches, -1, m_ref, True, progress=progress)
    return PatchMap(model, patches, marg, w, "offline")
