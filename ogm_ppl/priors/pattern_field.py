r"""A learned, translation-invariant field of ``w x w`` patterns at one or two scales (a prior for Chapter 5).

.. math:: \log \tilde p(m) = \sum_{(r, c)} \theta\big[\mathrm{code}(m_{r:r+w,\, c:c+w})\big]
          + \sum_{(i, j)} \theta_2\big[\mathrm{code}(\bar m_{i:i+w,\, j:j+w})\big],
          \qquad p(m) = \tilde p(m) / Z,

over every ``w x w`` window wholly inside the grid (first sum) and, with two scales, every window wholly
inside the ``2 x 2`` OR-pooled grid ``\bar m`` (``ceil(rows / 2) x ceil(cols / 2)``, a pooled cell the OR
of its block's in-grid cells; see :mod:`ogm_ppl.priors.compiled.field`) (Felzenszwalb & Oberlin,
multiscale fields of patterns, NeurIPS 2014). Unlike the tiled tables of Section 5.2.2, every window
position counts (no tiling seams), and with finite ``theta`` every map has positive probability. The
potentials are tied over the 8 symmetries of the square: ``theta`` is given by one value per orbit of
window codes (102 orbits for ``w = 3``; :func:`symmetry_orbits`, :func:`orbits_to_table`). ``log_prob``
omits ``log Z`` (``normalised = False``); the Gibbs kernels read ``w^2`` lookups per scale per cell.
Learned by :mod:`ogm_ppl.priors.learn_field` (pseudo-likelihood shrunk to a ``2 x 2`` field, then tempered to
the strongest coupling whose prior samples agree from the all-free and all-occupied maps, with a bias giving
them the training occupied share); shipped fits: :func:`load_field`, ``field:CORPUS``.
"""

from __future__ import annotations

import hashlib
import json
from functools import lru_cache
from pathlib import Path

import numpy as np
import torch

from ogm_ppl.io import read_npz
from ogm_ppl.priors.compiled.field import MAX_WINDOW, field_window_codes, pattern_field
from ogm_ppl.priors.local import LocalMapPrior, grid_shape

__all__ = [
    "FIELD_FORMAT_VERSION",
    "PatternFieldPrior",
    "field_from_file",
    "field_path",
    "load_field",
    "orbits_to_table",
    "pooled_grid",
    "save_field",
    "symmetry_orbits",
    "table_to_orbits",
]

FIELD_FORMAT_VERSION = 1
FITTED_DIR = Path(__file__).resolve().parents[1] / "fitted"


@lru_cache(maxsize=8)
def _orbits(w: int) -> tuple[np.ndarray, int]:
    n = w * w
    idx = np.arange(n).reshape(w, w)
    perms = []
    for k in range(4):
        r = np.rot90(idx, k)
        perms += [r.ravel(), r.T.ravel()]  # the 4 rotations and their transposes: the 8 symmetries
    codes = np.arange(1 << n, dtype=np.int64)
    bits = (codes[:, None] >> np.arange(n)) & 1
    images = np.stack([(bits[:, p] << np.arange(n)).sum(1) for p in perms], 1)  # code -> its 8 images
    rep = images.min(1)
    uniq, orbit = np.unique(rep, return_inverse=True)
    orbit = orbit.astype(np.int64)
    orbit.setflags(write=False)
    return orbit, len(uniq)


def symmetry_orbits(w: int = 3) -> tuple[np.ndarray, int]:
    """``(orbit_of, n_orbits)``: the orbit (under the 8 flips/rotations of the ``w x w`` window) of each of
    the ``2^(w w)`` codes, orbits numbered by their smallest code; ``n_orbits`` is 6 / 102 / 8548 for
    ``w`` = 2 / 3 / 4."""
    w = int(w)
    if not 1 <= w <= MAX_WINDOW:
        raise ValueError(f"window side must lie in 1..{MAX_WINDOW}, got {w}")
    return _orbits(w)


def orbits_to_table(params, w: int = 3) -> np.ndarray:
    """The ``2^(w w)`` table of per-orbit values (``n_orbits`` float64): ``table[code] = params[orbit(code)]``."""
    orbit, n = symmetry_orbits(w)
    p = np.asarray(params, np.float64).reshape(-1)
    if p.shape != (n,):
        raise ValueError(f"expected {n} orbit parameters for w = {w}, got {p.shape}")
    return p[orbit]


def table_to_orbits(table, w: int = 3) -> np.ndarray:
    """Per-orbit means of a ``2^(w w)`` table (the inverse of :func:`orbits_to_table` on tied tables)."""
    orbit, n = symmetry_orbits(w)
    t = np.asarray(table, np.float64).reshape(-1)
    if t.shape != orbit.shape:
        raise ValueError(f"expected a table of {len(orbit)} entries for w = {w}, got {t.shape}")
    return np.bincount(orbit, t, n) / np.bincount(orbit, minlength=n)


def _as_table(theta, w: int, what: str) -> np.ndarray:
    t = np.asarray(theta, np.float64).reshape(-1)
    orbit, n = symmetry_orbits(w)
    if t.shape == (n,) and n != len(orbit):
        t = t[orbit]
    if t.shape != orbit.shape:
        raise ValueError(f"{what} must be the {len(orbit)}-entry table or the {n} orbit parameters, got {t.shape}")
    if not np.isfinite(t).all():
        raise ValueError(f"{what} must be finite")
    return t


def pooled_grid(maps: torch.Tensor) -> torch.Tensor:
    """The ``2 x 2`` OR-pooled grid of ``B x R x C`` maps: ``B x ceil(R/2) x ceil(C/2)`` (past the edge
    reads as free)."""
    B, R, C = maps.shape
    x = torch.nn.functional.pad(maps, (0, C % 2, 0, R % 2))
    return x.reshape(B, (R + 1) // 2, 2, (C + 1) // 2, 2).amax((2, 4))


def _window_codes(x: torch.Tensor, w: int) -> torch.Tensor:
    """``B x (R-w+1) x (C-w+1)`` int64 codes of the ``w x w`` windows of ``B x R x C`` 0/1 maps."""
    B, R, C = x.shape
    if R < w or C < w:
        return torch.zeros(B, 0, 0, dtype=torch.int64)
    win = x.unfold(1, w, 1).unfold(2, w, 1)  # B x nr x nc x w x w
    weights = 2.0 ** torch.arange(w * w, dtype=torch.float64).reshape(w, w)
    return (win * weights).sum((-2, -1)).round().to(torch.int64)


class PatternFieldPrior(LocalMapPrior):
    r"""The pattern field ``log p~(m) = sum_windows theta[code] (+ sum_pooled windows theta2[code])``.

    Args:
        shape: grid shape ``(rows, cols)`` (or a :class:`~ogm_ppl.Grid`; a 1D grid ``(K,)`` is one row).
        theta: the ``2^(w w)`` table of log-potentials, or its :func:`symmetry_orbits` parameters (tied).
        w: window side (1..4; 3 by default).
        theta2: the scale-2 potentials on the pooled grid (same forms), or ``None`` for one scale.
        occupancy: the field's cell marginal ``P(m_k = 1)`` away from the edges (stored with a fit), the
            value of :meth:`outside_occupancy`; ``None``: estimated once by prior Gibbs sampling.

    >>> p = PatternFieldPrior((3, 4), np.zeros(102))
    >>> float(p.log_prob(torch.ones(12)))
    0.0
    """

    normalised = False

    def __init__(self, shape, theta, w: int = 3, theta2=None, occupancy: float | None = None) -> None:
        self.rows, self.cols, self.ndim = grid_shape(shape)
        self.shape = (self.cols,) if self.ndim == 1 else (self.rows, self.cols)
        self.num_cells = self.rows * self.cols
        self.w = int(w)
        self.theta = _as_table(theta, self.w, "theta")
        self.theta2 = None if theta2 is None else _as_table(theta2, self.w, "theta2")
        self.n_scales = 1 if theta2 is None else 2
        if occupancy is not None and not 0.0 <= float(occupancy) <= 1.0:
            raise ValueError(f"occupancy must lie in [0, 1], got {occupancy}")
        self.occupancy = None if occupancy is None else float(occupancy)
        if self.occupancy is not None:  # the "ogm" initial map's threshold (initial_map; else 0.5)
            self.mean_occupancy = self.occupancy
        self._compiled = pattern_field(self.rows, self.cols, self.w, self.theta, self.theta2)
        self._t1 = torch.from_numpy(self.theta)
        self._t2 = None if self.theta2 is None else torch.from_numpy(self.theta2)

    def __repr__(self) -> str:
        return f"PatternFieldPrior(shape={self.shape}, w={self.w}, scales={self.n_scales})"

    def log_prob(self, maps):
        """``log p~(m)`` (without ``-log Z``) for ``... x K`` maps -> ``...`` (float64, vectorised)."""
        maps = torch.as_tensor(maps, dtype=torch.float64)
        batch = maps.shape[:-1]
        x = (maps.reshape(-1, self.rows, self.cols) != 0).to(torch.float64)
        out = self._t1[_window_codes(x, self.w)].sum((-2, -1))
        if self._t2 is not None:
            out = out + self._t2[_window_codes(pooled_grid(x), self.w)].sum((-2, -1))
        return out.reshape(batch)

    def sample(self, sample_shape=(), generator=None, num_sweeps: int = 200):
        """Maps drawn by ``num_sweeps`` compiled single-cell Gibbs sweeps on the prior alone (from uniform noise)."""
        return self._gibbs_sample(sample_shape, generator, num_sweeps)

    def tempered(self, beta: float) -> PatternFieldPrior:
        """The field of ``beta * log p~`` (every potential times ``beta``; the marginal is re-estimated)."""
        return PatternFieldPrior(
            self.shape, self.theta * beta, self.w, None if self.theta2 is None else self.theta2 * beta
        )

    def outside_occupancy(self) -> float:
        """The field's cell marginal ``P(m_k = 1)`` (the fitted value, or a seeded estimate from 8 prior
        Gibbs chains of 48 x 48 cells, 300 sweeps, centre 32 x 32 cells of the last 100 sweeps)."""
        if self.occupancy is None:
            self.occupancy = estimate_occupancy(self.theta, self.w, self.theta2)
        return self.occupancy


def estimate_occupancy(theta, w, theta2=None, size: int = 48, chains: int = 8, sweeps: int = 300, seed: int = 0):
    """``P(m_k = 1)`` of the field away from the edges, by compiled prior Gibbs chains (see
    :meth:`PatternFieldPrior.outside_occupancy`)."""
    from ogm_ppl.priors.compiled import prior_gibbs_sweeps

    t2 = None if theta2 is None or (np.asarray(theta2) == 0).all() else theta2
    b = pattern_field(size, size, w, theta, t2)
    rng = np.random.default_rng(seed)
    maps = np.ascontiguousarray(rng.random((chains, size * size)) < 0.5, dtype=np.uint8)
    burn = sweeps - 100
    prior_gibbs_sweeps(b, maps, burn, seed)
    tot = 0.0
    for i in range(10):
        prior_gibbs_sweeps(b, maps, 10, seed + 1 + i)
        g = maps.reshape(chains, size, size)[:, 8:-8, 8:-8]
        tot += float(g.mean())
    return tot / 10


# ------------------------------------------------------------------ shipped fits
_KEYS = {"w": (), "theta": None, "occupancy": (), "theta2_scale1": None, "theta2_scale2": None, "occupancy2": ()}


def field_path(corpus: str) -> Path:
    """The shipped fit of ``corpus``: ``ogm_ppl/fitted/field_<corpus>.npz``."""
    return FITTED_DIR / f"field_{corpus}.npz"


def load_field(path) -> dict:
    """Read and validate a fitted pattern field (``np.load(allow_pickle=False)``).

    The file holds ``w`` (int), the one-scale fit ``theta`` (orbit parameters) and ``occupancy``, and the
    two-scale fit ``theta2_scale1``, ``theta2_scale2`` and ``occupancy2`` (the shipped fits; a file of
    :func:`save_field` may hold the one-scale fit alone). Returns them as a dict of numpy values; raises
    ``ValueError`` naming the path for a missing key, a wrong shape or a non-finite value.
    """
    path = Path(path)
    data = read_npz(path, "a pattern field written by save_field")
    two = {"theta2_scale1", "theta2_scale2", "occupancy2"}
    keys = dict(_KEYS) if two & set(data) else {k: v for k, v in _KEYS.items() if k not in two}  # one scale
    missing = sorted(set(keys) - set(data))
    if missing:
        raise ValueError(f"{path}: missing arrays {missing}")
    if data["w"].shape != () or not np.issubdtype(data["w"].dtype, np.integer):
        raise ValueError(f"{path}: 'w' must be an integer scalar")
    w = int(data["w"])
    if not 1 <= w <= MAX_WINDOW:
        raise ValueError(f"{path}: window side w = {w} outside 1..{MAX_WINDOW}")
    _, n = symmetry_orbits(w)
    for k, shape in keys.items():
        a = data[k]
        want = (n,) if shape is None else shape
        if a.shape != want:
            raise ValueError(f"{path}: {k!r} has shape {a.shape}, expected {want}")
        if not np.issubdtype(a.dtype, np.number) or not np.isfinite(a).all():
            raise ValueError(f"{path}: {k!r} must be finite numbers")
    for k in ("occupancy", "occupancy2") if "occupancy2" in keys else ("occupancy",):
        if not 0.0 <= float(data[k]) <= 1.0:
            raise ValueError(f"{path}: {k!r} = {float(data[k])} outside [0, 1]")
    return {k: (int(v) if k == "w" else np.asarray(v, np.float64)) for k, v in data.items() if k in _KEYS}


def save_field(path, field: PatternFieldPrior, field2: PatternFieldPrior | None = None) -> Path:
    """Write a fitted pattern field (one scale: ``field``; and optionally a two-scale one, ``field2``, of the
    same window side) in the format of the shipped fits, atomically: ``w``, the orbit parameters and each
    field's cell marginal (estimated now where the field has none). Read it back with :func:`field_from_file`
    (or :func:`load_field`). The potentials must be tied over the 8 symmetries, as every fit is."""
    from ogm_ppl.io import atomic_write

    for given in (field, field2):
        if given is not None and not isinstance(given, PatternFieldPrior):
            hint = " (a FieldFit: pass fit.prior(shape))" if hasattr(given, "best_gap") else ""
            raise TypeError(f"save_field: expected a PatternFieldPrior, got {type(given).__name__}{hint}")

    def orbits(table: np.ndarray, what: str) -> np.ndarray:
        params = table_to_orbits(table, field.w)
        if not np.allclose(orbits_to_table(params, field.w), table, rtol=0, atol=1e-12):
            raise ValueError(f"save_field: {what} is not tied over the 8 symmetries of the window")
        return params

    if field.theta2 is not None:
        raise ValueError("save_field: field is the one-scale fit; give a two-scale field as field2")
    arrays = {"w": np.int64(field.w), "theta": orbits(field.theta, "theta")}
    arrays["occupancy"] = np.float64(field.outside_occupancy())
    if field2 is not None:
        if field2.theta2 is None or field2.w != field.w:
            raise ValueError(f"save_field: field2 must be a two-scale field with w = {field.w}")
        arrays["theta2_scale1"] = orbits(field2.theta, "field2's theta")
        arrays["theta2_scale2"] = orbits(field2.theta2, "field2's theta2")
        arrays["occupancy2"] = np.float64(field2.outside_occupancy())
    path = Path(path)
    with atomic_write(path, "wb") as f:
        np.savez(f, **arrays)  # type: ignore[arg-type]
    return path


def field_from_file(path, shape, scales: int = 1) -> PatternFieldPrior:
    """The field of a file of :func:`save_field` (or a shipped fit), one or two scales, over ``shape``."""
    d = load_field(path)
    if scales == 2 and "theta2_scale1" not in d:
        raise ValueError(f"{path}: holds the one-scale field only")
    if scales == 1:
        return PatternFieldPrior(shape, d["theta"], d["w"], occupancy=float(d["occupancy"]))
    return PatternFieldPrior(
        shape, d["theta2_scale1"], d["w"], theta2=d["theta2_scale2"], occupancy=float(d["occupancy2"])
    )


def field_by_name(corpus: str, shape, scales: int = 1) -> PatternFieldPrior:
    """The shipped field of ``corpus`` (one or two scales) over a grid of ``shape``."""
    d = load_field(field_path(corpus))
    if scales == 1:
        return PatternFieldPrior(shape, d["theta"], d["w"], occupancy=float(d["occupancy"]))
    return PatternFieldPrior(
        shape, d["theta2_scale1"], d["w"], theta2=d["theta2_scale2"], occupancy=float(d["occupancy2"])
    )


def sha256_of(path) -> str:
    """The sha256 of a file's bytes (provenance)."""
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def provenance(corpus: str) -> dict:
    """The provenance JSON beside a shipped fit (``field_<corpus>.json``)."""
    p = field_path(corpus).with_suffix(".json")
    try:
        return json.loads(p.read_text())
    except (OSError, ValueError) as e:
        raise ValueError(f"{p}: unreadable provenance ({e})") from None


def window_code_counts(grid: np.ndarray, known: np.ndarray | None, w: int) -> np.ndarray:
    """Counts of the ``2^(w w)`` codes over the windows of a 2D 0/1 ``grid`` wholly in known cells."""
    g = np.ascontiguousarray(grid != 0, np.uint8)
    codes = field_window_codes(g, w)
    if known is not None:
        kn = field_window_codes(np.ascontiguousarray(~np.asarray(known, bool), np.uint8), w)
        codes = codes[kn == 0]
    return np.bincount(codes.ravel(), minlength=1 << (w * w)).astype(np.int64)
