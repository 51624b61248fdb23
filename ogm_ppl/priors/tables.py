r"""Learned prior tables (Sections 5.2.1-5.2.3): the container, npz I/O, and the shipped artefacts.

Code convention (everywhere in this package)
--------------------------------------------
A window of ``h x w`` cells is flattened in row-major order; cell ``i`` of the flattened window is bit ``i``
of the integer code, little-endian: ``code = sum_i m_i << i``. So for a 3 x 3 window the top-left cell is bit
0, the top-right bit 2, the centre bit 4, the bottom-right bit 8.

* **border16** of a 5 x 5 window: the 16 ring cells, in row-major order of the 5 x 5 window, i.e. window
  positions ``(0, 1, 2, 3, 4, 5, 9, 10, 14, 15, 19, 20, 21, 22, 23, 24)``; ring cell ``j`` is bit ``j``.
* **inner9** of a 5 x 5 window: its centre 3 x 3 (window positions ``6, 7, 8, 11, 12, 13, 16, 17, 18``) coded as a
  3 x 3 window.
* **border8** of a 3 x 3 window: the 8 neighbours of the centre in row-major order (positions
  ``0, 1, 2, 3, 5, 6, 7, 8``); neighbour ``j`` is bit ``j``.
* **lines**: a ``1 x L`` window, bit ``i`` = ``i``-th cell along the line.

Arrays of a :class:`PriorTables` (all ``int64`` counts; ``N`` = distinct stored 5 x 5 codes)
-----------------------------------------------------------------------------------------------
::

    ``cell_counts``   ``(2,)``      free / occupied cells (known cells only); ``lam = cell_counts[1] / sum``.
    ``counts3x3``     ``(512,)``    3 x 3 windows by code (all windows wholly inside known cells).
    ``codes5x5``      ``(N,)``      sorted distinct 5 x 5 codes (25 bits);  ``counts5x5`` ``(N,)`` their counts.
    ``pair_counts``   ``(4, 2, 2)`` joint counts ``[k, a, b]`` of the cell pair ``(r, c), (r + dr, c + dc)`` for the
                                    offsets ``PAIR_OFFSETS = ((0, 1), (1, 0), (1, 1), (1, -1))``.
    ``line_counts``   ``(2**L,)``   ``1 x L`` windows along rows and along columns (read top-down), ``L = line_length``.
    ``run_counts``    ``(2, R + 1)`` lengths of complete runs (bounded on both ends by known cells of the other
                                    value) of free (row 0) / occupied (row 1) cells along rows and columns;
                                    bin ``R`` holds runs of length ``>= R``; bin 0 is unused.
    ``truncated_mass`` ``()``       count of 5 x 5 windows dropped by ``min_count_5x5`` (0 when nothing dropped).

Derived on demand (not stored; they re-index the arrays above exactly):
:meth:`PriorTables.border_table` (3 x 3 given its 16-cell border, from the 5 x 5 table; CSR by border, and
``.triples()`` -> ``(border_codes, inner_codes, counts)``), :meth:`PriorTables.counts1given8` (``(256, 2)``, centre
given its 8 neighbours, from ``counts3x3``) and :meth:`PriorTables.border1_triples`, :meth:`PriorTables.line_table`
(``1 x L`` windows, ``L <= line_length``) and :meth:`PriorTables.line_border_triples` (1D run given its 2 border
cells).

Feeding the prior classes::

    t = tables_by_name("generated")
    PatchTablePrior(shape, codes=np.arange(512), counts=t.counts3x3)             # 3 x 3, Section 5.2.2
    PatchTablePrior(shape, codes=t.codes5x5, counts=t.counts5x5, patch=(5, 5))   # 5 x 5
    BorderPatchPrior(shape, *t.border_table().triples())                         # 3 x 3 | 16, Section 5.2.3
    BorderPatchPrior(shape, *t.border1_triples(), inner=(1, 1))                  # 1 | 8
    IndependentPrior(t.lam); t.psi(4)                                            # cell prior, MRF edge weight

With ``symmetries = 8`` every table counts the 8 flipped/rotated copies of each map (the thesis's "all eight
permutations"), i.e. it equals the sum of the tables of the 8 transformed maps.
"""

from __future__ import annotations

import errno
import hashlib
import json
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path

import numpy as np

from ogm_ppl.io import atomic_write, read_npz

__all__ = [
    "FORMAT_VERSION",
    "PAIR_OFFSETS",
    "BORDER16_INDEX",
    "INNER9_INDEX",
    "BORDER8_INDEX",
    "PriorTables",
    "BorderTable",
    "save_tables",
    "load_tables",
    "tables_by_name",
    "available_tables",
    "split_border_inner",
    "encode_window",
    "decode_code",
]

FORMAT_VERSION = 1
PAIR_OFFSETS: tuple[tuple[int, int], ...] = ((0, 1), (1, 0), (1, 1), (1, -1))
BORDER16_INDEX = np.array([0, 1, 2, 3, 4, 5, 9, 10, 14, 15, 19, 20, 21, 22, 23, 24], dtype=np.int64)
INNER9_INDEX = np.array([6, 7, 8, 11, 12, 13, 16, 17, 18], dtype=np.int64)
BORDER8_INDEX = np.array([0, 1, 2, 3, 5, 6, 7, 8], dtype=np.int64)
FITTED_DIR = Path(__file__).resolve().parent.parent / "fitted"

_ARRAYS = {  # name -> (ndim or None for any, dtype kind)
    "cell_counts": 1,
    "counts3x3": 1,
    "codes5x5": 1,
    "counts5x5": 1,
    "pair_counts": 3,
    "line_counts": 1,
    "run_counts": 2,
    "truncated_mass": 0,
}


def encode_window(window) -> int:
    """Integer code of a 0/1 window: row-major flatten, ``code = sum_i m_i << i``.

    >>> encode_window([[1, 0, 0], [0, 0, 0], [0, 0, 1]])
    257
    """
    bits = np.asarray(window, dtype=np.int64).reshape(-1)
    return int((bits << np.arange(bits.size, dtype=np.int64)).sum())


def decode_code(code, shape) -> np.ndarray:
    """Inverse of :func:`encode_window` (vectorised over ``code``): ``(..., *shape)`` bool.

    >>> decode_code(257, (3, 3)).astype(int).tolist()
    [[1, 0, 0], [0, 0, 0], [0, 0, 1]]
    """
    code = np.asarray(code, dtype=np.int64)
    n = int(np.prod(shape))
    bits = (code[..., None] >> np.arange(n, dtype=np.int64)) & 1
    return bits.astype(bool).reshape(*code.shape, *shape)


def _gather_bits(codes: np.ndarray, index: np.ndarray) -> np.ndarray:
    """New code whose bit ``j`` is bit ``index[j]`` of ``codes``."""
    codes = np.asarray(codes, dtype=np.int64)
    out = np.zeros_like(codes)
    for j, i in enumerate(index):
        out |= ((codes >> int(i)) & 1) << j
    return out


def split_border_inner(codes5x5) -> tuple[np.ndarray, np.ndarray]:
    """``(border16, inner9)`` codes of 5 x 5 window codes (see the module docstring)."""
    return _gather_bits(codes5x5, BORDER16_INDEX), _gather_bits(codes5x5, INNER9_INDEX)


@dataclass(frozen=True)
class BorderTable:
    r"""Counts of a patch given its border, grouped by border (CSR) for compiled lookups.

    ``borders`` ``(B,)`` sorted distinct border codes; configurations of border ``borders[b]`` are
    ``inner[offsets[b]:offsets[b + 1]]`` with counts ``counts[offsets[b]:offsets[b + 1]]`` (inner codes sorted
    ascending within a border). Look a border up with ``np.searchsorted(borders, code)``.
    ``p(inner | border) = counts / counts[slice].sum()``.
    """

    borders: np.ndarray
    offsets: np.ndarray
    inner: np.ndarray
    counts: np.ndarray

    def lookup(self, border: int) -> tuple[np.ndarray, np.ndarray]:
        """``(inner codes, counts)`` seen with ``border`` (empty arrays if the border never occurred)."""
        b = int(np.searchsorted(self.borders, border))
        if b == self.borders.size or self.borders[b] != border:
            return self.inner[:0], self.counts[:0]
        s, e = self.offsets[b], self.offsets[b + 1]
        return self.inner[s:e], self.counts[s:e]

    def triples(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(border_code, inner_code, count)`` flat arrays, one row per observed pair."""
        return np.repeat(self.borders, np.diff(self.offsets)), self.inner, self.counts


@dataclass(frozen=True, eq=False)
class PriorTables:
    """Counted statistics of binary maps (see the module docstring for the array layout)."""

    cell_counts: np.ndarray
    counts3x3: np.ndarray
    codes5x5: np.ndarray
    counts5x5: np.ndarray
    pair_counts: np.ndarray
    line_counts: np.ndarray
    run_counts: np.ndarray
    truncated_mass: int = 0
    provenance: dict = field(default_factory=dict)

    # -- simple statistics -------------------------------------------------------------------------------------
    @property
    def lam(self) -> float:
        """Cell prior ``p(m_k = 1)``: the share of occupied (known) cells (the thesis found 0.234)."""
        return float(self.cell_counts[1] / max(int(self.cell_counts.sum()), 1))

    @property
    def symmetries(self) -> int:
        return int(self.provenance.get("symmetries", 1))

    @property
    def line_length(self) -> int:
        return int(np.log2(self.line_counts.size))

    def pair_stats(self, connectivity: int = 4) -> tuple[int, int]:
        """``(equal, unequal)`` neighbour-pair counts for 4- or 8-connectivity (for an MRF's ``psi``)."""
        k = {4: 2, 8: 4}[connectivity]
        p = self.pair_counts[:k]
        return int(p[:, 0, 0].sum() + p[:, 1, 1].sum()), int(p[:, 0, 1].sum() + p[:, 1, 0].sum())

    def psi(self, connectivity: int = 4) -> float:
        """Empirical ``psi = P(unequal) / P(equal)`` of a neighbour pair (Section 5.2.1's edge weight)."""
        eq, ne = self.pair_stats(connectivity)
        return ne / max(eq, 1)

    # -- derived tables ----------------------------------------------------------------------------------------
    def counts1given8(self) -> np.ndarray:
        """``(256, 2)`` counts of the centre cell (column) given its 8-cell border code (row), from ``counts3x3``."""
        codes = np.arange(512, dtype=np.int64)
        border = _gather_bits(codes, BORDER8_INDEX)
        centre = (codes >> 4) & 1
        out = np.zeros((256, 2), dtype=np.int64)
        np.add.at(out, (border, centre), self.counts3x3)
        return out

    def mrf_fit(self, connectivity: int = 4) -> tuple[float, float]:
        r"""``(lambda, psi)`` of the MRF of Section 5.2.1 fitted to the corpus by maximum pseudo-likelihood.

        The MRF's conditional is :math:`l(m_k \mid \text{nbrs}) = l(\lambda) + (n_0 - n_1) \log\psi`
        (:class:`~ogm_ppl.priors.MRFPrior`); every 3 x 3 window of the corpus gives one centre cell and its
        4 (or 8) neighbours, so the pseudo-likelihood is a logistic regression of the centre on
        ``x = n0 - n1`` with intercept ``l(lambda)`` and slope ``log psi``, solved by Newton's method.
        (The raw ratio of unequal to equal neighbour pairs, :meth:`psi`, is not this fit: it couples
        neighbours far too strongly.)
        """
        c = self.counts1given8().astype(np.float64)  # 256 x 2
        codes = np.arange(256, dtype=np.int64)
        # border8 bit order: window positions 0, 1, 2, 3, 5, 6, 7, 8; the 4-neighbours are 1, 3, 5, 7
        four = np.array([1, 3, 4, 6]) if connectivity == 4 else np.arange(8)
        if connectivity not in (4, 8):
            raise ValueError(f"connectivity must be 4 or 8, got {connectivity}")
        n1 = ((codes[:, None] >> four[None, :]) & 1).sum(1).astype(np.float64)
        x = (len(four) - n1) - n1
        w0, w1 = c[:, 0], c[:, 1]
        if w1.sum() == 0 or w0.sum() == 0:
            raise ValueError("the corpus has only one cell value: no MRF to fit")
        theta = np.array([np.log(w1.sum() / w0.sum()), 0.0])
        X = np.stack([np.ones_like(x), x], 1)
        for _ in range(100):
            p = 1.0 / (1.0 + np.exp(-(X @ theta)))
            n = w0 + w1
            grad = X.T @ (w1 - n * p)
            H = (X * (n * p * (1 - p))[:, None]).T @ X + 1e-9 * np.eye(2)
            step = np.linalg.solve(H, grad)
            theta += step
            if np.abs(step).max() < 1e-12:
                break
        lam = float(1.0 / (1.0 + np.exp(-theta[0])))
        return lam, float(np.exp(theta[1]))

    def border1_triples(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(border8_code, centre, count)`` of every observed (8-neighbour border, centre) pair."""
        c = self.counts1given8()
        b, i = np.nonzero(c)
        return b.astype(np.int64), i.astype(np.int64), c[b, i]

    def line_border_triples(self, length: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """1D: ``(border, inner, count)`` of a run of ``length`` cells given the cell on each side.

        From ``line_table(length + 2)``: border bit 0 = the cell before, bit 1 = the cell after; inner bit
        ``i`` = run cell ``i``.
        """
        t = self.line_table(length + 2)
        codes = np.nonzero(t)[0].astype(np.int64)
        border = (codes & 1) | (((codes >> (length + 1)) & 1) << 1)
        inner = (codes >> 1) & ((1 << length) - 1)
        return border, inner, t[codes]

    @cached_property
    def _border9(self) -> BorderTable:
        border, inner = split_border_inner(self.codes5x5)
        order = np.lexsort((inner, border))
        border, inner, counts = border[order], inner[order], self.counts5x5[order]
        borders, starts = np.unique(border, return_index=True)
        offsets = np.append(starts, border.size).astype(np.int64)
        return BorderTable(borders, offsets, inner, counts)

    def border_table(self) -> BorderTable:
        """3 x 3 (inner9) given the 16-cell border, re-indexed from the stored 5 x 5 table."""
        return self._border9

    def line_table(self, length: int) -> np.ndarray:
        """``(2**length,)`` counts of ``1 x length`` windows, marginalised from ``line_counts``.

        Windows are those that start where a full ``line_length`` window fits (they are its first cells).
        """
        if not 1 <= length <= self.line_length:
            raise ValueError(f"line_table: length must lie in 1..{self.line_length}, got {length}")
        return self.line_counts.reshape(-1, 2**length).sum(0)

    def patch_probs(self, size: int = 3, mass: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
        """``(codes, probs)`` of ``size x size`` (3 or 5) patches, most likely first, truncated to the smallest
        set carrying ``mass`` of the probability (the thesis keeps 99.9%)."""
        if size == 3:
            codes, counts = np.arange(512, dtype=np.int64), self.counts3x3
        elif size == 5:
            codes, counts = self.codes5x5, self.counts5x5
        else:
            raise ValueError(f"patch_probs: size must be 3 or 5, got {size}")
        keep = counts > 0
        codes, counts = codes[keep], counts[keep]
        order = np.lexsort((codes, -counts))
        codes, probs = codes[order], counts[order] / counts.sum()
        n = int(np.searchsorted(np.cumsum(probs), mass - 1e-12) + 1)
        return codes[:n], probs[:n]

    def summary(self) -> dict:
        """The thesis's statistics (Section 5.2.2-5.2.3) as a dict of plain numbers."""
        c3 = self.counts3x3
        n3 = int(c3.sum())
        c5 = self.counts5x5
        n5 = int(c5.sum()) + int(self.truncated_mass)
        full5 = (1 << 25) - 1
        bt = self.border_table()
        per_border = np.diff(bt.offsets)
        c18 = self.counts1given8()
        seen8 = c18.sum(1) > 0
        return {
            "lambda": self.lam,
            "windows3x3": n3,
            "free3x3": float(c3[0] / max(n3, 1)),
            "occupied3x3": float(c3[511] / max(n3, 1)),
            "distinct3x3": int((c3 > 0).sum()),
            "distinct3x3_999": int(self.patch_probs(3, 0.999)[0].size) if n3 else 0,
            "windows5x5": n5,
            "free5x5": float(c5[self.codes5x5 == 0].sum() / max(n5, 1)),
            "occupied5x5": float(c5[self.codes5x5 == full5].sum() / max(n5, 1)),
            "distinct5x5": int(c5.size),
            "distinct5x5_999": int(self.patch_probs(5, 0.999)[0].size) if c5.size else 0,
            "distinct_border16": int(bt.borders.size),
            "max_inner_per_border16": int(per_border.max()) if per_border.size else 0,
            "single_inner_border16_share": float((per_border == 1).mean()) if per_border.size else 0.0,
            "distinct_border8": int(seen8.sum()),
            "mixed_border8": int(((c18 > 0).sum(1) == 2).sum()),
            "psi4": self.psi(4),
            "psi8": self.psi(8),
            "truncated_mass": int(self.truncated_mass),
        }

    # -- I/O ---------------------------------------------------------------------------------------------------
    def save(self, path) -> Path:
        return save_tables(self, path)


def _validate(arrays: dict, where: str) -> None:
    def bad(msg):
        raise ValueError(f"prior tables {where}: {msg}")

    for name, ndim in _ARRAYS.items():
        if name not in arrays:
            bad(f"missing array {name!r}")
        a = arrays[name]
        if a.dtype.kind not in "iu":
            bad(f"array {name!r} must hold integers, got dtype {a.dtype}")
        if a.ndim != ndim:
            bad(f"array {name!r} must have {ndim} dimensions, got shape {a.shape}")
        if (a < 0).any():
            bad(f"array {name!r} has negative counts")
    if arrays["cell_counts"].shape != (2,):
        bad(f"cell_counts must have shape (2,), got {arrays['cell_counts'].shape}")
    if arrays["counts3x3"].shape != (512,):
        bad(f"counts3x3 must have shape (512,), got {arrays['counts3x3'].shape}")
    if arrays["pair_counts"].shape != (4, 2, 2):
        bad(f"pair_counts must have shape (4, 2, 2), got {arrays['pair_counts'].shape}")
    c5, n5 = arrays["codes5x5"], arrays["counts5x5"]
    if c5.shape != n5.shape:
        bad(f"codes5x5 {c5.shape} and counts5x5 {n5.shape} differ in shape")
    if c5.size and (c5.max() >= 1 << 25 or (np.diff(c5) <= 0).any()):
        bad("codes5x5 must be strictly increasing 25-bit codes")
    lc = arrays["line_counts"].size
    if lc < 2 or lc & (lc - 1):
        bad(f"line_counts must have a power-of-two length >= 2, got {lc}")
    if arrays["run_counts"].shape[0] != 2:
        bad(f"run_counts must have shape (2, R + 1), got {arrays['run_counts'].shape}")
    if (arrays["cell_counts"] == 0).any():
        bad(f"cell_counts {arrays['cell_counts'].tolist()} must count free and occupied cells (lambda in (0, 1))")
    if arrays["counts3x3"].sum() == 0:
        bad("counts3x3 counts no window")


def _content_digest(arrays: dict) -> str:
    """SHA-256 of the tables' arrays (as int64, in :data:`_ARRAYS` order): written beside them by
    :func:`save_tables` and checked by :func:`load_tables`, so an array edited after saving is refused."""
    h = hashlib.sha256()
    for name in _ARRAYS:
        a = np.ascontiguousarray(arrays[name], dtype=np.int64)
        h.update(f"{name}{a.shape}".encode())
        h.update(a.tobytes())
    return h.hexdigest()


def save_tables(tables: PriorTables, path) -> Path:
    """Write ``tables`` to ``path`` (npz, compressed, no pickles) atomically (:func:`~ogm_ppl.io.atomic_write`:
    an error names ``path``)."""
    path = Path(path)
    arrays = {name: np.asarray(getattr(tables, name), dtype=np.int64) for name in _ARRAYS}
    arrays["codes5x5"] = arrays["codes5x5"].astype(np.int32)  # 25 bits fit
    _validate(arrays, str(path))
    prov = {k: v for k, v in tables.provenance.items() if k != "sha256"}
    meta = json.dumps(
        {
            "format": "ogm_ppl.prior_tables",
            "format_version": FORMAT_VERSION,
            **prov,
            "sha256": _content_digest(arrays),
        }
    )
    with atomic_write(path) as f:
        # numpy's stub: **kwds might also bind its `allow_pickle: bool`; our keys are table names
        np.savez_compressed(f, meta=np.array(meta), **arrays)  # type: ignore[arg-type]
    return path


def load_tables(path) -> PriorTables:
    """Read tables written by :func:`save_tables`; a malformed file raises ``ValueError`` naming ``path``, as
    does one whose arrays were edited after saving (the SHA-256 :func:`save_tables` records no longer matches;
    files written without one are read unchecked)."""
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(errno.ENOENT, "no such prior tables file", str(path))
    data = read_npz(path, "prior tables written by save_tables")
    if "meta" not in data:
        raise ValueError(f"prior tables {path}: missing 'meta' (not an ogm_ppl prior-tables file)")
    try:
        meta = json.loads(str(data.pop("meta")))
    except json.JSONDecodeError as e:
        raise ValueError(f"prior tables {path}: 'meta' is not valid JSON ({e})") from e
    if meta.get("format") != "ogm_ppl.prior_tables":
        raise ValueError(f"prior tables {path}: format is {meta.get('format')!r}, expected 'ogm_ppl.prior_tables'")
    if meta.get("format_version") != FORMAT_VERSION:
        raise ValueError(
            f"prior tables {path}: format_version {meta.get('format_version')!r} is not supported "
            f"(this version reads {FORMAT_VERSION})"
        )
    _validate(data, str(path))
    if "sha256" in meta and meta["sha256"] != _content_digest(data):  # files written before it have none
        raise ValueError(f"prior tables {path}: the arrays differ from those saved (their SHA-256 does not match)")
    provenance = {k: v for k, v in meta.items() if k not in ("format", "format_version", "sha256")}
    return PriorTables(
        cell_counts=data["cell_counts"].astype(np.int64),
        counts3x3=data["counts3x3"].astype(np.int64),
        codes5x5=data["codes5x5"].astype(np.int64),
        counts5x5=data["counts5x5"].astype(np.int64),
        pair_counts=data["pair_counts"].astype(np.int64),
        line_counts=data["line_counts"].astype(np.int64),
        run_counts=data["run_counts"].astype(np.int64),
        truncated_mass=int(data["truncated_mass"]),
        provenance=provenance,
    )


def available_tables() -> list[str]:
    """Names of the shipped tables (``ogm_ppl/fitted/prior_<name>.npz``)."""
    return sorted(p.stem[len("prior_") :] for p in FITTED_DIR.glob("prior_*.npz"))


def tables_by_name(name: str) -> PriorTables:
    """Load a shipped table set by name, e.g. ``tables_by_name("generated")`` (see :func:`available_tables`)."""
    path = FITTED_DIR / f"prior_{name}.npz"
    if not path.is_file():
        raise KeyError(f"no shipped prior tables named {name!r}; available: {available_tables()}")
    return load_tables(path)
