"""Replaying a log into an :class:`~ogm_ppl.inference.online.OnlineMap` one scan at a time
(:func:`replay`), with snapshots of the marginals and the time each scan took.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from ogm_ppl.grid import Grid
from ogm_ppl.inference.online._map import OnlineMap
from ogm_ppl.scans import Scans
from ogm_ppl.sensors import SensorModel


@dataclass
class Replay:
    """What :func:`replay` returns: the final marginals (``K``), the observed cells (``K`` bool), the
    snapshots ``(scans so far, K marginals)``, the seconds each scan took (add + sweeps) and the chain."""

    probabilities: np.ndarray
    observed: np.ndarray
    snapshots: list[tuple[int, np.ndarray]]
    seconds_per_scan: np.ndarray
    online: OnlineMap


def replay(
    grid: Grid,
    scans: Scans,
    sensor: SensorModel,
    prior,
    *,
    burn_in: int = 0,
    sweeps: int = 100,
    snapshot_every: int | None = None,
    progress: bool = False,
    **online_kw,
) -> Replay:
    """Replay ``scans`` one scan at a time into an :class:`OnlineMap` (``online_kw``: its options), then
    run ``burn_in`` full sweeps and ``sweeps`` full sweeps whose mean is the map. ``snapshot_every = k``
    keeps the marginals (of the sweeps since the latest scan) after every ``k``-th scan."""

    if snapshot_every is not None and snapshot_every < 1:
        raise ValueError(f"snapshot_every must be a positive number of scans, got {snapshot_every}")
    om = OnlineMap(grid, sensor, prior, **online_kw)
    times, snaps = feed_scans(om, scans, snapshot_every, progress, lambda: om.marginals)
    om.sweep(burn_in, focus=False)
    om.reset_marginals()
    om.sweep(sweeps, focus=False)
    return Replay(om.marginals.numpy().copy(), om.observed, snaps, times, om)


def feed_scans(om, scans: Scans, snapshot_every: int | None, progress: bool, read) -> tuple[np.ndarray, list]:
    """Add ``scans`` to the online map ``om`` one at a time (``om.add_scans``), skipping scans without a reading:
    the seconds of each scan (``S``, 0 where skipped) and ``(scans so far, read() as numpy)`` after every
    ``snapshot_every``-th scan. A bar on a terminal; elsewhere a plain line every 10 s once it has taken 10 s."""
    from ogm_ppl.progress import Progress

    S = scans.num_scans
    times = np.zeros(S)
    snaps: list[tuple[int, np.ndarray]] = []
    assert scans.valid is not None  # Scans.__post_init__ always sets the S x B mask
    with Progress(S, "online scans", unit="scan", enabled=progress, after=10.0) as bar:
        for i in range(S):
            bar.update()
            if not scans.valid[i].any():
                continue  # a scan without a reading adds nothing
            t0 = time.perf_counter()
            om.add_scans(_one(scans, i))
            times[i] = time.perf_counter() - t0
            if snapshot_every is not None and (i + 1) % snapshot_every == 0:
                snaps.append((i + 1, read().numpy().copy()))
    return times, snaps


def _one(scans: Scans, i: int) -> Scans:
    assert scans.valid is not None
    return Scans(
        scans.poses[i : i + 1],
        scans.angles[i : i + 1],
        scans.ranges[i : i + 1],
        scans.max_range,
        valid=scans.valid[i : i + 1],
        min_range=scans.min_range,
    )
