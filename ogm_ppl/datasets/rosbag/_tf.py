"""Laser poses through the transform tree of ``/tf`` and ``/tf_static``: quaternion algebra, slerp of each
dynamic link and the chain ``map_frame -> ... -> laser frame`` composed in 3D, as tf2 does."""

from __future__ import annotations

import itertools
from collections import defaultdict
from pathlib import Path

import numpy as np

from ogm_ppl.datasets.rosbag._errors import BagFormatError
from ogm_ppl.datasets.rosbag._poses import _bracket


def _yaw(qx, qy, qz, qw):
    """Yaw (rotation about z) of unit quaternions: ``atan2(2 (w z + x y), 1 - 2 (y^2 + z^2))``."""
    return np.arctan2(2.0 * (qw * qz + qx * qy), 1.0 - 2.0 * (qy * qy + qz * qz))


def _qmul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton products of quaternions ``(..., 4)`` stored ``(x, y, z, w)``."""
    ax, ay, az, aw = np.moveaxis(a, -1, 0)
    bx, by, bz, bw = np.moveaxis(b, -1, 0)
    return np.stack(
        [
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
            aw * bw - ax * bx - ay * by - az * bz,
        ],
        axis=-1,
    )


def _qrot(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """``v`` rotated by unit quaternions ``q``: ``v + 2 w (u x v) + 2 u x (u x v)``, ``u = q.xyz``."""
    u, w = q[..., :3], q[..., 3:4]
    t = 2.0 * np.cross(u, v)
    return v + w * t + np.cross(u, t)


def _slerp(q0: np.ndarray, q1: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Shortest-arc spherical interpolation of unit quaternions (rows), weights ``w`` in [0, 1]."""
    d = np.sum(q0 * q1, axis=-1)
    q1 = np.where((d < 0)[:, None], -q1, q1)
    d = np.abs(d)
    theta = np.arccos(np.clip(d, -1.0, 1.0))
    s = np.sin(theta)
    small = s < 1e-9
    with np.errstate(all="ignore"):
        a = np.where(small, 1.0 - w, np.sin((1.0 - w) * theta) / s)
        b = np.where(small, w, np.sin(w * theta) / s)
    q = a[:, None] * q0 + b[:, None] * q1
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    return np.where((w == 0)[:, None], q0, q)


def _poses_from_tf(path: Path, links: list, frames: list[str], stamps: np.ndarray, tol_ns: int, map_frame: str):
    """Laser poses ``S x 3`` through the transform tree, which scans have one, which lasers are mounted
    upside down (their z axis points down in the map: beam angles turn the other way), and the stamps of
    the first dynamic link's samples."""
    by_link: dict[tuple[str, str], list] = defaultdict(list)
    parent: dict[str, str] = {}
    for rec in links:
        p, c = rec[0], rec[1]
        if c in parent and parent[c] != p:
            raise BagFormatError(path, f"frame {c!r} has two parents, {parent[c]!r} and {p!r}", topic="/tf")
        parent[c] = p
        by_link[(p, c)].append(rec)
    out = np.zeros((len(stamps), 3))
    ok = np.zeros(len(stamps), dtype=bool)
    flipped = np.zeros(len(stamps), dtype=bool)
    first_dynamic = np.zeros(0, dtype=np.int64)
    for frame in sorted(set(frames)):
        sel = np.array([f == frame for f in frames], dtype=bool)
        chain = [frame]
        while chain[-1] != map_frame and chain[-1] in parent and len(chain) < 1000:
            chain.append(parent[chain[-1]])
        if chain[-1] != map_frame:
            raise BagFormatError(
                path,
                f"no transform chain from {map_frame!r} to the laser frame {frame!r} in /tf and /tf_static "
                f"(the frames above {frame!r}: {' -> '.join(chain[1:]) or 'none'})",
            )
        t_s = stamps[sel]
        q = np.tile([0.0, 0.0, 0.0, 1.0], (len(t_s), 1))
        tv = np.zeros((len(t_s), 3))
        good = np.ones(len(t_s), dtype=bool)
        for child, par in itertools.pairwise(chain):  # compose map -> ... -> laser from the top
            recs = by_link[(par, child)]
            dyn = [r for r in recs if not r[5]]
            if not dyn:  # a static link: its last value
                lt, lq = np.tile(recs[-1][3], (len(t_s), 1)), np.tile(recs[-1][4], (len(t_s), 1))
            else:
                dyn.sort(key=lambda r: r[2])
                st = np.array([r[2] for r in dyn], dtype=np.int64)
                if not len(first_dynamic):
                    first_dynamic = st
                T = np.array([r[3] for r in dyn])
                Q = np.array([r[4] for r in dyn])
                i0, i1, w, ok_l = _bracket(st, t_s, tol_ns)
                good &= ok_l
                lt = T[i0] + w[:, None] * (T[i1] - T[i0])
                lq = _slerp(Q[i0], Q[i1], w)
            # (tv, q) is the laser in `child`'s frame; the link is `child` in `par`: laser in `par`
            tv = lt + _qrot(lq, tv)
            q = _qmul(lq, q)
        out[sel, 0], out[sel, 1] = tv[:, 0], tv[:, 1]
        out[sel, 2] = _yaw(q[:, 0], q[:, 1], q[:, 2], q[:, 3])  # the heading of the laser's x axis
        ok[sel] = good
        flipped[sel] = _qrot(q, np.array([0.0, 0.0, 1.0]))[:, 2] < 0
    return out, ok, flipped, first_dynamic
