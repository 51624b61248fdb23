r"""Seeded ground-truth maps in the spirit of the thesis's Fig. 5.9 (Section 5.2.2).

The thesis learned its patch priors from ten hand-made 500 x 500 maps "designed to represent a different type of
environment", each with a 20-cell occupied border and "varying shapes and thicknesses of walls and distances
between them". Those maps are not published, so this module draws maps of the same families from a seed:

``"office"``
    rooms from a recursive (BSP) split of the interior, walls 1-3 cells thick, one door gap per wall, a little
    furniture (solid blocks) in some rooms.
``"corridor"``
    solid (occupied) interior with carved corridors 12-40 cells wide and rooms opening onto them through doors.
``"cluttered"``
    a few large rooms crowded with blocks, pillars, discs and L-shaped obstacles.
``"hall"``
    open halls with pillars, free-standing partial walls and (sometimes) a diagonal wall.

Every map is a ``H x W`` bool array, ``True`` = occupied, with an occupied outer border (``border`` cells,
default 20 as in Fig. 5.9). Drawing is rectangle slicing with numpy (a 500 x 500 map takes a few ms).

>>> m = generate_map("office", seed=0)
>>> m.shape, m.dtype, bool(m[0].all() and m[:, -1].all())
((500, 500), dtype('bool'), True)
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence

import numpy as np

__all__ = ["KINDS", "generate_map", "generate_corpus", "iter_corpus"]

KINDS: tuple[str, ...] = ("office", "corridor", "cluttered", "hall")


def _rng(seed) -> np.random.Generator:
    if isinstance(seed, np.random.Generator):
        return seed
    return np.random.default_rng(seed)


def _hwall(m, r, c0, c1, t, rng, doors=1, door=(8, 20)):
    """Horizontal wall of thickness ``t`` on rows ``r..r+t-1`` from column ``c0`` to ``c1`` with door gaps."""
    m[r : r + t, c0:c1] = True
    for _ in range(doors):
        w = int(rng.integers(door[0], door[1] + 1))
        if c1 - c0 > w + 4:
            s = int(rng.integers(c0 + 2, c1 - w - 1))
            m[r : r + t, s : s + w] = False


def _vwall(m, c, r0, r1, t, rng, doors=1, door=(8, 20)):
    m[r0:r1, c : c + t] = True
    for _ in range(doors):
        w = int(rng.integers(door[0], door[1] + 1))
        if r1 - r0 > w + 4:
            s = int(rng.integers(r0 + 2, r1 - w - 1))
            m[s : s + w, c : c + t] = False


def _bsp(rng, r0, r1, c0, c1, min_size, max_size, out):
    """Recursive split of the rectangle ``[r0, r1) x [c0, c1)``; appends (r0, r1, c0, c1, split, axis)."""
    h, w = r1 - r0, c1 - c0
    can_r, can_c = h >= 2 * min_size, w >= 2 * min_size
    small = h <= max_size and w <= max_size
    if (not can_r and not can_c) or (small and rng.random() < 0.5):
        out.append((r0, r1, c0, c1))
        return
    axis = 0 if (can_r and (not can_c or h > w or (h == w and rng.random() < 0.5))) else 1
    if axis == 0:
        s = int(rng.integers(r0 + min_size, r1 - min_size + 1))
        _bsp(rng, r0, s, c0, c1, min_size, max_size, out)
        _bsp(rng, s, r1, c0, c1, min_size, max_size, out)
    else:
        s = int(rng.integers(c0 + min_size, c1 - min_size + 1))
        _bsp(rng, r0, r1, c0, s, min_size, max_size, out)
        _bsp(rng, r0, r1, s, c1, min_size, max_size, out)


def _rooms_with_walls(m, rng, lo, hi, min_size, max_size, t_range=(1, 3)):
    """BSP rooms inside ``[lo[0], hi[0]) x [lo[1], hi[1])``; walls on each room's low edges (shared walls)."""
    rooms: list[tuple[int, int, int, int]] = []
    _bsp(rng, lo[0], hi[0], lo[1], hi[1], min_size, max_size, rooms)
    for r0, r1, c0, c1 in rooms:
        t = int(rng.integers(t_range[0], t_range[1] + 1))
        if r0 > lo[0]:
            _hwall(m, r0, c0, c1 + t, t, rng, doors=1 + int(rng.random() < 0.2))
        if c0 > lo[1]:
            _vwall(m, c0, r0, r1 + t, t, rng, doors=1 + int(rng.random() < 0.2))
    return rooms


def _block(m, rng, r0, r1, c0, c1, size=(3, 25)):
    """A solid rectangle of random size placed inside the given box (if it fits)."""
    h = int(rng.integers(size[0], size[1] + 1))
    w = int(rng.integers(size[0], size[1] + 1))
    if r1 - r0 <= h + 2 or c1 - c0 <= w + 2:
        return
    r = int(rng.integers(r0 + 1, r1 - h))
    c = int(rng.integers(c0 + 1, c1 - w))
    m[r : r + h, c : c + w] = True


def _disc(m, rng, r0, r1, c0, c1, radius=(2, 12)):
    rad = int(rng.integers(radius[0], radius[1] + 1))
    if r1 - r0 <= 2 * rad + 2 or c1 - c0 <= 2 * rad + 2:
        return
    r = int(rng.integers(r0 + rad + 1, r1 - rad - 1))
    c = int(rng.integers(c0 + rad + 1, c1 - rad - 1))
    y, x = np.ogrid[-rad : rad + 1, -rad : rad + 1]
    m[r - rad : r + rad + 1, c - rad : c + rad + 1] |= (y * y + x * x) <= rad * rad


def _diagonal_wall(m, rng, lo, hi, t):
    """A straight wall at a random angle, ``t`` cells thick, drawn by stamping points along the segment."""
    p0 = rng.uniform(lo, hi)
    p1 = rng.uniform(lo, hi)
    n = int(np.ceil(np.abs(p1 - p0).max() * 2)) + 1
    pts = np.rint(p0[None] + np.linspace(0.0, 1.0, n)[:, None] * (p1 - p0)[None]).astype(int)
    for dr in range(t):
        for dc in range(t):
            rr = np.clip(pts[:, 0] + dr, 0, m.shape[0] - 1)
            cc = np.clip(pts[:, 1] + dc, 0, m.shape[1] - 1)
            m[rr, cc] = True


def _office(m, rng, lo, hi):
    rooms = _rooms_with_walls(m, rng, lo, hi, min_size=int(rng.integers(40, 70)), max_size=160)
    for r0, r1, c0, c1 in rooms:
        if rng.random() < 0.4:
            for _ in range(int(rng.integers(1, 4))):
                _block(m, rng, r0 + 4, r1 - 4, c0 + 4, c1 - 4, size=(4, 18))


def _corridor(m, rng, lo, hi):
    m[lo[0] : hi[0], lo[1] : hi[1]] = True
    # main corridors: horizontal and vertical bands
    nh, nv = int(rng.integers(1, 3)), int(rng.integers(1, 3))
    bands = []
    for axis, k in ((0, nh), (1, nv)):
        span = hi[axis] - lo[axis]
        for i in range(k):
            w = int(rng.integers(12, 41))
            centre = lo[axis] + int((i + 1) * span / (k + 1) + rng.integers(-30, 31))
            a = int(np.clip(centre - w // 2, lo[axis] + 5, hi[axis] - w - 5))
            bands.append((axis, a, a + w))
            if axis == 0:
                m[a : a + w, lo[1] + 5 : hi[1] - 5] = False
            else:
                m[lo[0] + 5 : hi[0] - 5, a : a + w] = False
    # rooms along the corridors, opening through a door gap
    for _ in range(int(rng.integers(14, 26))):
        axis, a, b = bands[int(rng.integers(len(bands)))]
        other = 1 - axis
        rh, rw = int(rng.integers(40, 120)), int(rng.integers(40, 120))
        t = int(rng.integers(1, 4))
        side = int(rng.integers(2))
        pos = int(rng.integers(lo[other] + 10, max(lo[other] + 11, hi[other] - (rw if axis == 0 else rh) - 10)))
        if axis == 0:  # corridor is a horizontal band rows a..b
            r0 = a - t - rh if side == 0 else b + t
            r0 = int(np.clip(r0, lo[0] + 3, hi[0] - rh - 3))
            m[r0 : r0 + rh, pos : pos + rw] = False
            dr = (r0 + rh, a) if side == 0 else (b, r0)
            d0 = pos + int(rng.integers(2, max(3, rw - 14)))
            m[min(dr) : max(dr), d0 : d0 + int(rng.integers(8, 14))] = False
        else:
            c0 = a - t - rw if side == 0 else b + t
            c0 = int(np.clip(c0, lo[1] + 3, hi[1] - rw - 3))
            m[pos : pos + rh, c0 : c0 + rw] = False
            dc = (c0 + rw, a) if side == 0 else (b, c0)
            d0 = pos + int(rng.integers(2, max(3, rh - 14)))
            m[d0 : d0 + int(rng.integers(8, 14)), min(dc) : max(dc)] = False


def _cluttered(m, rng, lo, hi):
    rooms = _rooms_with_walls(m, rng, lo, hi, min_size=int(rng.integers(90, 150)), max_size=460)
    for r0, r1, c0, c1 in rooms:
        area = (r1 - r0) * (c1 - c0)
        for _ in range(int(area / 2500 * rng.uniform(0.3, 0.9))):
            u = rng.random()
            if u < 0.45:
                _block(m, rng, r0 + 3, r1 - 3, c0 + 3, c1 - 3, size=(2, 20))
            elif u < 0.7:
                _disc(m, rng, r0 + 3, r1 - 3, c0 + 3, c1 - 3, radius=(2, 10))
            else:  # an L-shape: two blocks sharing a corner
                h, w = int(rng.integers(10, 40)), int(rng.integers(10, 40))
                t = int(rng.integers(1, 4))
                if r1 - r0 > h + 10 and c1 - c0 > w + 10:
                    r = int(rng.integers(r0 + 5, r1 - h - 4))
                    c = int(rng.integers(c0 + 5, c1 - w - 4))
                    m[r : r + h, c : c + t] = True
                    m[r + h - t : r + h, c : c + w] = True


def _hall(m, rng, lo, hi):
    rooms = _rooms_with_walls(m, rng, lo, hi, min_size=int(rng.integers(150, 230)), max_size=460)
    for r0, r1, c0, c1 in rooms:
        # a grid of pillars
        p = int(rng.integers(3, 9))
        step = int(rng.integers(40, 90))
        round_ = rng.random() < 0.4
        for r in range(r0 + step // 2, r1 - p - 2, step):
            for c in range(c0 + step // 2, c1 - p - 2, step):
                if round_:
                    y, x = np.ogrid[-p : p + 1, -p : p + 1]
                    rr, cc = slice(max(r - p, 0), r + p + 1), slice(max(c - p, 0), c + p + 1)
                    if r - p >= 0 and c - p >= 0:
                        m[rr, cc] |= (y * y + x * x) <= p * p
                else:
                    m[r : r + p, c : c + p] = True
        # free-standing partial walls
        for _ in range(int(rng.integers(0, 4))):
            t = int(rng.integers(1, 4))
            if rng.random() < 0.5 and c1 - c0 > 60:
                r = int(rng.integers(r0 + 5, r1 - 5))
                a = int(rng.integers(c0 + 5, c1 - 50))
                m[r : r + t, a : a + int(rng.integers(20, min(150, c1 - a - 3)))] = True
            elif r1 - r0 > 60:
                c = int(rng.integers(c0 + 5, c1 - 5))
                a = int(rng.integers(r0 + 5, r1 - 50))
                m[a : a + int(rng.integers(20, min(150, r1 - a - 3))), c : c + t] = True
    if rng.random() < 0.5:
        _diagonal_wall(m, rng, np.array(lo) + 10, np.array(hi) - 10, int(rng.integers(2, 4)))


_DRAW = {"office": _office, "corridor": _corridor, "cluttered": _cluttered, "hall": _hall}


def generate_map(kind: str = "office", shape: tuple[int, int] = (500, 500), seed=0, border: int = 20) -> np.ndarray:
    """One ground-truth map of the given ``kind`` (see :data:`KINDS`).

    Args:
        kind: ``"office"``, ``"corridor"``, ``"cluttered"`` or ``"hall"``.
        shape: ``H x W`` cells (default 500 x 500 as in Fig. 5.9; at least 60 x 60).
        seed: an int, a :class:`numpy.random.SeedSequence` or a :class:`numpy.random.Generator`.
        border: thickness of the occupied outer border in cells (Fig. 5.9 uses 20; at least 1).

    Returns:
        ``H x W`` bool array, ``True`` = occupied.
    """
    if kind not in _DRAW:
        raise ValueError(f"generate_map: unknown kind {kind!r}; expected one of {KINDS}")
    h, w = (int(s) for s in shape)
    if h < 60 or w < 60:
        raise ValueError(f"generate_map: shape must be at least 60 x 60, got {shape}")
    if not 1 <= border <= min(h, w) // 4:
        raise ValueError(f"generate_map: border must lie in 1..{min(h, w) // 4}, got {border}")
    rng = _rng(seed)
    m = np.zeros((h, w), dtype=bool)
    lo, hi = (border, border), (h - border, w - border)
    _DRAW[kind](m, rng, lo, hi)
    m[:border] = m[-border:] = True
    m[:, :border] = m[:, -border:] = True
    return m


def iter_corpus(
    n: int,
    shape: tuple[int, int] = (500, 500),
    seed: int = 0,
    kinds: Sequence[str] = KINDS,
    border: int = 20,
) -> Iterator[np.ndarray]:
    """Yield ``n`` maps; map ``i`` has kind ``kinds[i % len(kinds)]`` and its own child seed of ``seed``.

    Map ``i`` does not depend on ``n`` (child seeds come from ``SeedSequence(seed).spawn``).
    """
    kinds = tuple(kinds)
    if not kinds:
        raise ValueError("iter_corpus: kinds must not be empty")
    for i, child in enumerate(np.random.SeedSequence(seed).spawn(int(n))):
        yield generate_map(kinds[i % len(kinds)], shape, np.random.default_rng(child), border=border)


def generate_corpus(
    n: int,
    shape: tuple[int, int] = (500, 500),
    seed: int = 0,
    kinds: Sequence[str] = KINDS,
    border: int = 20,
) -> list[np.ndarray]:
    """A list of ``n`` maps (see :func:`iter_corpus`); deterministic for a seed.

    >>> a = generate_corpus(2, (100, 100), seed=3); b = generate_corpus(2, (100, 100), seed=3)
    >>> all((x == y).all() for x, y in zip(a, b))
    True
    """
    return list(iter_corpus(n, shape, seed, kinds, border))
