r"""The online predictive map: the amortised guide's map ``q(m_k = 1 | z_1, ..., z_t)`` kept up to date as scans
arrive, each scan recomputing only what it changes (:class:`OnlineGuideMap`).

**What a scan changes.** The guide's features
(:func:`~ogm_ppl.inference.variational.amortised_features.evidence_features`) are functions of per-cell sums
over the ray-cell entries, ``n_pass``, ``n_hit`` and the evidence
``l_k = sum_n Delta(kappa_{n,k}; z_n)``, and of the pinned (pose) cells. :meth:`OnlineGuideMap.add_scans`
ray-casts the new scans only, adds their entries' terms
(:func:`~ogm_ppl.inference.variational.amortised_features.ray_terms`) to the kept sums, recomputes the features
of the cells whose terms were not all zero (and of the new pose cells) and hands the cells whose features
changed to :class:`~ogm_ppl.inference.variational.amortised_incremental.IncrementalLogits`, which recomputes,
layer by layer, the cells within the network's reach ``sum_l d_l`` of them.

**Equal to the map from scratch.** The sums are kept as ``1 x K`` float64 tensors and the new entries are added
with the same ``index_add_`` in the same (ray, kappa) order as the offline features add every entry, so each
cell's sum is the same sequence of float64 additions: the counts are exact integers and the evidence is the
same to the last bit. The features are then those of ``evidence_features`` on a model of every scan so far (to
the last bit where torch's vectorised and scalar ``log1p`` agree: at most one float32 ulp apart otherwise), and
the logits are those of a full pass over them to float32 rounding: every recomputed cell's sums are the
convolution's in another order, within the recursive-summation bound of
:mod:`~ogm_ppl.inference.variational.amortised_fast`; a cell not recomputed keeps logits computed from the
same inputs. Nothing drifts with the number of scans: no sum is updated by differences.

**Cost.** A scan of ``n`` entries costs its ray casting, ``O(n)`` for the sums and features, and
``sum_l |S_l| 9 C_{l-1} C_l`` multiply-adds for the network (``S_l``: the changed cells grown by the first
``l`` dilations); the symmetrised map (``symmetrize=True``) 8 times that. Memory: the features and the
activations of every layer but the last, ``4 (H + 2P)(W + 2P)(C_0 + sum_{l<n} C_l)`` bytes (times 8 symmetrised;
``P`` the largest dilation), and ``25 K`` bytes of sums and masks.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from ogm_ppl.grid import Grid
from ogm_ppl.inference.online._replay import feed_scans
from ogm_ppl.inference.variational.amortised_features import base_channels, phase_channels, ray_terms
from ogm_ppl.inference.variational.amortised_incremental import IncrementalLogits
from ogm_ppl.models.occupancy import entry_table, range_to_kappa
from ogm_ppl.raycast import Rays, raycast
from ogm_ppl.scans import Scans

__all__ = ["GuideReplay", "OnlineGuideMap", "replay_guide"]


class OnlineGuideMap:
    r"""The amortised guide's map over every scan added so far, updated per scan where the scan changes it
    (module docstring :mod:`ogm_ppl.inference.online._guide`).

    Args:
        grid: the 2D grid (``H x W = K`` cells); every scan's poses must lie in it.
        guide: an :class:`~ogm_ppl.inference.variational.AmortisedGuide` (its network, update term and
            tile phase are read once; its ``symmetrize`` is the default of ``symmetrize``).
        symmetrize: the mean over the 8 turns and flips of the grid (8 times the work and memory).
        threads: torch threads of an update's convolutions (one a layer, over the tiles it recomputes;
            default 1: on a machine other jobs load, threads that wait cost more than they give); torch's
            own thread count is restored after each update.

    Attributes:
        recomputed: cells whose logits the latest :meth:`add_scans` recomputed.

    >>> from ogm_ppl import Grid, Scans
    >>> from ogm_ppl.inference.variational import AmortisedGuide
    >>> grid = Grid((12, 12), 1.0)
    >>> om = OnlineGuideMap(grid, AmortisedGuide(channels=4, dilations=(1, 2), phase=(0, 0)))
    >>> om.add_scans(Scans(poses=[6.5, 6.5, 0.0], angles=[0.0, 1.5], ranges=[3.2, 4.0], max_range=8.0))
    >>> om.probabilities.shape
    torch.Size([144])
    """

    def __init__(self, grid: Grid, guide, *, symmetrize: bool | None = None, threads: int = 1) -> None:
        if grid.ndim != 2:
            raise ValueError(f"the online guide map needs a 2D grid, got shape {grid.shape}")
        sym = guide.symmetrize if symmetrize is None else symmetrize
        if sym and guide.arch.phase != (0, 0):
            raise ValueError(
                f"a guide with tile-phase channels (phase {guide.arch.phase}) cannot be symmetrised: the tiling "
                "does not turn with the grid"
            )
        if not isinstance(threads, int) or isinstance(threads, bool) or threads < 1:
            raise ValueError(f"threads must be a positive integer, got {threads!r}")
        self.grid, self.guide, self.symmetrize, self.threads = grid, guide, bool(sym), threads
        self._delta = guide.arch.delta
        H, W = grid.shape
        K = grid.num_cells
        self._n_pass = torch.zeros(1, K, dtype=torch.float64)
        self._n_hit = torch.zeros(1, K, dtype=torch.float64)
        self._lo = torch.zeros(1, K, dtype=torch.float64)
        self._pinned = torch.zeros(K, dtype=torch.bool)
        self._reached = np.zeros(K, bool)
        ph = phase_channels(H, W, guide.arch.phase)
        self._phase = None if ph is None else ph.reshape(ph.shape[0], K)
        x0 = self._rows(torch.arange(K)).T.reshape(-1, H, W)
        self._inc = IncrementalLogits(guide.net, x0, self.symmetrize)
        self._scans = 0
        self.recomputed = 0

    @property
    def num_scans(self) -> int:
        return self._scans

    def _rows(self, k: torch.Tensor) -> torch.Tensor:
        """The feature rows of cells ``k`` from the kept sums: ``n x C`` float32."""
        chans = base_channels(self._n_pass[0, k], self._n_hit[0, k], self._lo[0, k], self._pinned[k].double())
        x = torch.stack(chans, 1)
        if self._phase is not None:
            x = torch.cat([x, self._phase[:, k].T], 1)
        return x.to(torch.float32)

    def add_scans(self, scans: Scans) -> None:
        """Add ``scans``: ray-cast them, add their terms to the kept sums and recompute the logits they reach.
        Raises ``ValueError`` for scans without a reading or poses outside the grid (before any change)."""
        if not isinstance(scans, Scans):
            raise TypeError(f"add_scans takes Scans, got {type(scans).__name__}")
        if scans.num_scans == 0 or scans.num_valid == 0:
            raise ValueError(
                f"add_scans got {scans.num_scans} scans with no reading (every beam invalid or none): nothing to add"
            )
        self.add_rays(raycast(self.grid, scans))  # raises on poses outside the grid
        self._scans += scans.num_scans

    def add_rays(self, rays: Rays) -> None:
        """Add the rays of some scans (:func:`~ogm_ppl.raycast.raycast` on this map's grid)."""
        if rays.grid != self.grid:
            raise ValueError("rays were cast on a different grid than the map's")
        if rays.num_rays == 0:
            raise ValueError("add_rays: no ray to add")
        F = torch.from_numpy(rays.max_range_cells()).to(torch.float64)
        z = torch.where(torch.from_numpy(rays.is_max.copy()), F, torch.from_numpy(rays.range_cells).double())
        is_max = (z >= F)[None]  # as evidence_features on the model's own readings
        passed, hit, lo = ray_terms(rays, range_to_kappa(entry_table(rays), z)[None], is_max, self._delta)
        cells = torch.from_numpy(rays.cells)
        self._n_pass.index_add_(1, cells, passed)
        self._n_hit.index_add_(1, cells, hit)
        self._lo.index_add_(1, cells, lo)
        pose = torch.from_numpy(rays.cells[rays.offsets[:-1]])
        self._pinned[pose] = True
        some = ((passed != 0) | (hit != 0) | (lo != 0))[0]
        k = torch.unique(torch.cat([cells[some], pose]))
        rows = self._rows(k)
        old = self._inc._x[self._inc._flat(k)]
        diff = (rows != old).any(1)
        prev = torch.get_num_threads()
        torch.set_num_threads(self.threads)
        try:
            self.recomputed = int(self._inc.update_cells(k[diff], rows[diff]).sum())
        finally:
            torch.set_num_threads(prev)
        self._reached |= rays.reached()

    @property
    def logits(self) -> torch.Tensor:
        """``K`` float64: the guide's logits over every scan so far (pinned cells hold the network's output)."""
        return self._inc.logits.reshape(-1).to(torch.float64)

    @property
    def probabilities(self) -> torch.Tensor:
        """``K`` float64: ``q(m_k = 1 | z)`` (pinned cells 0), as
        :meth:`~ogm_ppl.inference.variational.AmortisedGuide.marginals` on a model of every scan so far."""
        return torch.where(self._pinned, 0.0, torch.sigmoid(self.logits))

    @property
    def layer_work(self) -> list[tuple[int, int]]:
        """Per layer of the network, the cells the latest :meth:`add_scans` recomputed and the cells of the
        tiles it ran the convolution on (:attr:`IncrementalLogits.last_work
        <ogm_ppl.inference.variational.amortised_incremental.IncrementalLogits.last_work>`)."""
        return list(self._inc.last_work)

    @property
    def features(self) -> torch.Tensor:
        """``C x H x W`` float32: the features the logits are of (a copy)."""
        return self._inc.features

    @property
    def pinned(self) -> torch.Tensor:
        """``K`` bool: cells holding a pose (the offline model's ``known_free``)."""
        return self._pinned.clone()

    @property
    def observed(self) -> np.ndarray:
        """``K`` bool: cells some beam reached (:meth:`~ogm_ppl.raycast.Rays.reached`)."""
        return self._reached.copy()


@dataclass
class GuideReplay:
    """What :func:`replay_guide` returns: the final map (``K``), the observed cells (``K`` bool), the snapshots
    ``(scans so far, K probabilities)``, the seconds each scan took and the online map."""

    probabilities: np.ndarray
    observed: np.ndarray
    snapshots: list[tuple[int, np.ndarray]]
    seconds_per_scan: np.ndarray
    online: OnlineGuideMap


def replay_guide(
    grid: Grid,
    scans: Scans,
    guide,
    *,
    symmetrize: bool | None = None,
    snapshot_every: int | None = None,
    progress: bool = False,
) -> GuideReplay:
    """Replay ``scans`` one scan at a time into an :class:`OnlineGuideMap`; ``snapshot_every = k`` keeps the map
    after every ``k``-th scan. Scans without a reading are skipped (they change nothing)."""
    if snapshot_every is not None and snapshot_every < 1:
        raise ValueError(f"snapshot_every must be a positive number of scans, got {snapshot_every}")
    om = OnlineGuideMap(grid, guide, symmetrize=symmetrize)
    times, snaps = feed_scans(om, scans, snapshot_every, progress, lambda: om.probabilities)
    return GuideReplay(om.probabilities.numpy().copy(), om.observed, snaps, times, om)
