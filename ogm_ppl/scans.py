"""Range scans: robot poses, beam angles, ranges and the sensor's maximum range.

A scan is taken from one pose ``x_s = (x, y, yaw)`` with ``B`` beams at angles relative to the yaw.
Per-reading poses (``x_n`` of Section 2.1) are scans of one beam. Readings are validated on
construction: NaN, infinite or negative ranges, ranges over ``max_range`` (unless the caller asks for them
to be read as max-range readings), mismatched shapes and non-finite poses raise ``ValueError`` naming the
field and the first offending index.

Real sensors report beams that are not readings at all: no return (the Intel log's 81.83 m), a value
below the sensor's minimum range, or padding where scans have different beam counts. Such beams are
marked ``valid = False``: they are neither a hit nor a max-range reading, are never validated and are
left out of ray casting and mapping (the thesis drops them, Section 6.2). Turning a no-return beam into
a max-range reading instead would paint free space through the wall it missed; a reader that wants that
sets the range to ``max_range`` itself.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ["Scans"]


def _first_bad(mask: np.ndarray) -> tuple[int, ...]:
    return tuple(int(i) for i in np.argwhere(mask)[0])


@dataclass(frozen=True)
class Scans:
    """Validated range readings.

    Args:
        poses: ``S x 3`` array of ``(x, y, yaw)`` in metres and radians (a ``3`` vector for one scan).
        angles: beam angles relative to the yaw, ``B`` (shared by all scans) or ``S x B``.
        ranges: ``S x B`` ranges in metres (``B`` for one scan).
        max_range: the sensor's maximum range in metres. A reading equal to it is a max-range reading.
        over_range: ``"error"`` (default) rejects readings above ``max_range``; ``"max"`` reads them as
            max-range readings; ``"drop"`` marks them invalid.
        valid: optional ``S x B`` boolean mask; False marks beams that are not readings (see the module
            docstring). Their ranges are not checked and are stored as 0.
        min_range: readings below it (metres, ``>= 0``) are marked invalid.

    Attributes:
        is_max: ``S x B`` boolean, True where a valid reading is a max-range reading.
        valid: ``S x B`` boolean, True for the beams that are readings.

    >>> s = Scans(poses=[0.0, 0.0, 0.0], angles=[0.0, np.pi / 2], ranges=[1.0, 4.0], max_range=4.0)
    >>> s.num_readings, s.is_max.tolist()
    (2, [[False, True]])
    """

    poses: np.ndarray
    angles: np.ndarray
    ranges: np.ndarray
    max_range: float
    over_range: str = "error"
    valid: np.ndarray | None = None
    min_range: float = 0.0
    is_max: np.ndarray = field(init=False)

    def __post_init__(self) -> None:
        poses = np.asarray(self.poses, dtype=float)
        if poses.ndim == 1:
            poses = poses[None, :]
        if poses.ndim != 2 or poses.shape[1] != 3:
            raise ValueError(f"Scans.poses must have shape S x 3 (x, y, yaw), got {poses.shape}")
        S = poses.shape[0]
        ranges = np.asarray(self.ranges, dtype=float)
        if ranges.ndim == 1:
            ranges = ranges[None, :] if S == 1 else ranges[:, None]
        if ranges.ndim != 2 or ranges.shape[0] != S:
            raise ValueError(f"Scans.ranges must have shape S x B with S = {S} poses, got {np.shape(self.ranges)}")
        B = ranges.shape[1]
        angles = np.asarray(self.angles, dtype=float)
        if angles.ndim == 0:
            angles = angles[None]
        if angles.ndim == 1:
            if angles.shape[0] != B:
                raise ValueError(f"Scans.angles has {angles.shape[0]} beams but Scans.ranges has {B} per scan")
            angles = np.broadcast_to(angles, (S, B))
        if angles.shape != (S, B):
            raise ValueError(f"Scans.angles must have shape B or S x B = {(S, B)}, got {angles.shape}")
        mr = float(self.max_range)
        if not np.isfinite(mr) or mr <= 0:
            raise ValueError(f"Scans.max_range must be a positive finite number, got {self.max_range!r}")
        if self.over_range not in ("error", "max", "drop"):
            raise ValueError(f"Scans.over_range must be 'error', 'max' or 'drop', got {self.over_range!r}")
        min_range = float(self.min_range)
        if not (np.isfinite(min_range) and 0.0 <= min_range < mr):
            raise ValueError(f"Scans.min_range must lie in [0, max_range = {mr}), got {self.min_range!r}")
        if self.valid is None:
            valid = np.ones((S, B), dtype=bool)
        else:
            valid = np.asarray(self.valid)
            if valid.dtype != bool:
                raise ValueError(f"Scans.valid must be a boolean mask, got dtype {valid.dtype}")
            if valid.ndim == 1 and S == 1:
                valid = valid[None, :]
            if valid.shape != (S, B):
                raise ValueError(f"Scans.valid must have shape S x B = {(S, B)}, got {valid.shape}")
            valid = valid.copy()
        ranges = np.where(valid, ranges, 0.0)
        bad = ~np.isfinite(poses)
        if bad.any():
            raise ValueError(f"Scans.poses has a non-finite value at index {_first_bad(bad)}")
        bad = ~np.isfinite(angles)
        if bad.any():
            raise ValueError(f"Scans.angles has a non-finite value at index {_first_bad(bad)}")
        bad = np.isnan(ranges)
        if bad.any():
            raise ValueError(
                f"Scans.ranges is NaN at index {_first_bad(bad)}: mark beams with no reading invalid instead "
                "(valid=..., an S x B bool mask; give them any finite range)"
            )
        bad = np.isinf(ranges)
        if bad.any():
            raise ValueError(f"Scans.ranges is infinite at index {_first_bad(bad)}")
        bad = ranges < 0
        if bad.any():
            i = _first_bad(bad)
            raise ValueError(f"Scans.ranges is negative ({ranges[i]}) at index {i}")
        over = ranges > mr
        if self.over_range == "drop":
            valid &= ~over
            ranges = np.where(over, 0.0, ranges)
            over = np.zeros_like(over)
        if over.any() and self.over_range == "error":
            i = _first_bad(over)
            raise ValueError(
                f"Scans.ranges exceeds max_range = {mr} ({ranges[i]}) at index {i}; pass "
                "over_range='max' to read such readings as max-range readings"
            )
        ranges = np.minimum(ranges, mr)
        short = valid & (ranges < min_range)
        valid &= ~short
        ranges = np.where(short, 0.0, ranges)
        is_max = valid & (ranges >= mr)
        for name, value in (
            ("poses", poses),
            ("angles", angles),
            ("ranges", ranges),
            ("valid", valid),
            ("is_max", is_max),
        ):
            value = np.ascontiguousarray(value)
            value.setflags(write=False)
            object.__setattr__(self, name, value)
        object.__setattr__(self, "max_range", mr)
        object.__setattr__(self, "min_range", min_range)

    @property
    def num_scans(self) -> int:
        """S."""
        return self.ranges.shape[0]

    @property
    def beams_per_scan(self) -> int:
        """B."""
        return self.ranges.shape[1]

    @property
    def num_readings(self) -> int:
        """N = S * B beams, valid or not (ray ``r`` of :func:`~ogm_ppl.raycast.raycast` came from the
        flat beam index ``rays.reading[r]``)."""
        return self.ranges.size

    @property
    def num_valid(self) -> int:
        """Beams that are readings (hits or max range)."""
        assert self.valid is not None  # Scans.__post_init__ always sets the S x B mask
        return int(self.valid.sum())

    def subsample(self, pose_step: int = 1, beam_step: int = 1, pose_fraction: float | None = None) -> Scans:
        """Every ``pose_step``-th scan (or an evenly spaced ``pose_fraction`` of them) and every
        ``beam_step``-th beam: the sparser experiments of Table 6.5 (half the beams, 10 % of the poses)."""
        S = self.num_scans
        if pose_step < 1 or beam_step < 1:
            raise ValueError(f"pose_step and beam_step must be >= 1, got {pose_step}, {beam_step}")
        if pose_fraction is not None:
            if not 0.0 < pose_fraction <= 1.0:
                raise ValueError(f"pose_fraction must lie in (0, 1], got {pose_fraction}")
            n = max(1, round(S * pose_fraction))
            keep = np.unique(np.floor(np.arange(n) * (S / n)).astype(np.int64))
        else:
            keep = np.arange(0, S, pose_step)
        assert self.valid is not None  # Scans.__post_init__ always sets the S x B mask
        return Scans(
            self.poses[keep],
            self.angles[keep, ::beam_step],
            self.ranges[keep, ::beam_step],
            self.max_range,
            valid=self.valid[keep, ::beam_step],
            min_range=self.min_range,
        )

    def select(self, which) -> Scans:
        """The scans ``which`` picks, in its order: scan indices (a stretch of a log,
        ``scans.select(range(100, 160))``) or an ``S`` boolean mask (the scans taken inside a region,
        ``scans.select(grid.contains(scans.poses[:, :2]))``, as a map of part of a building needs: every pose
        must lie on the grid)."""
        idx = np.asarray(which)
        S = self.num_scans
        if idx.dtype == bool:
            if idx.shape != (S,):
                raise ValueError(f"Scans.select: a mask must have shape ({S},), got {idx.shape}")
            idx = np.flatnonzero(idx)
        elif idx.size and not np.issubdtype(idx.dtype, np.integer):
            raise ValueError(f"Scans.select: scan indices must be integers or an S mask, got dtype {idx.dtype}")
        idx = idx.astype(np.int64).reshape(-1)
        if idx.size == 0:
            raise ValueError("Scans.select: no scan selected")
        if idx.min() < 0 or idx.max() >= S:
            raise ValueError(f"Scans.select: scan indices must lie in [0, {S}), got {idx.min()}..{idx.max()}")
        assert self.valid is not None  # Scans.__post_init__ always sets the S x B mask
        return Scans(
            self.poses[idx],
            self.angles[idx],
            self.ranges[idx],
            self.max_range,
            valid=self.valid[idx],
            min_range=self.min_range,
        )

    def extent(self) -> tuple[float, float, float, float]:
        """``(xmin, xmax, ymin, ymax)`` in metres of the poses and the end points of every valid hit."""
        hit = self.valid & ~self.is_max
        ang = self.world_angles()
        px = np.broadcast_to(self.poses[:, :1], hit.shape)[hit]
        py = np.broadcast_to(self.poses[:, 1:2], hit.shape)[hit]
        xs = np.concatenate([self.poses[:, 0], px + self.ranges[hit] * np.cos(ang[hit])])
        ys = np.concatenate([self.poses[:, 1], py + self.ranges[hit] * np.sin(ang[hit])])
        return float(xs.min()), float(xs.max()), float(ys.min()), float(ys.max())

    def world_angles(self) -> np.ndarray:
        """Beam directions in the world frame, ``S x B`` (yaw + beam angle)."""
        return self.poses[:, 2:3] + self.angles

    @classmethod
    def one_d(
        cls,
        ranges,
        max_range: float,
        position: float = 0.5,
        direction: int = 1,
        over_range: str = "error",
    ) -> Scans:
        """Readings of a stationary robot on a 1D grid (Section 2.3.1): all from ``position`` (metres)
        looking along ``+x`` (``direction=1``) or ``-x`` (``-1``). One scan per reading."""
        if direction not in (1, -1):
            raise ValueError(f"Scans.one_d direction must be 1 or -1, got {direction!r}")
        ranges = np.atleast_1d(np.asarray(ranges, dtype=float))
        n = ranges.shape[0]
        yaw = 0.0 if direction == 1 else np.pi
        poses = np.tile([position, 0.0, yaw], (n, 1))
        return cls(
            poses=poses,
            angles=np.zeros(1),
            ranges=ranges[:, None],
            max_range=max_range,
            over_range=over_range,
        )
