r"""Learning prior tables by counting windows of example maps with torch (Sections 5.2.1-5.2.3).

The thesis sampled 10^10 random 5 x 5 patches (each flipped and rotated into its 8 variants) from ten
500 x 500 maps and sub-sampled 3 x 3 patches, single cells, and patches given their 16-cell border from them.
Here every window of every map is counted exactly (no sampling): window codes are built from shifted views
of the map (a stride trick, equivalent to ``torch.nn.functional.unfold`` without the ``25 x`` copy), windows
touching an unknown cell are skipped, and codes are counted with ``torch.bincount`` (3 x 3, lines) or
``torch.unique`` (sparse 5 x 5). The 8 dihedral variants of a window are obtained by permuting the bits of the
distinct codes, which equals counting the 8 transformed maps. Maps are processed one at a time, so memory
stays bounded by one map and the running sparse table.

Code conventions and the table layout are documented in :mod:`ogm_ppl.priors.tables`.

>>> import numpy as np
>>> m = np.zeros((6, 6), dtype=bool); m[:, 0] = True
>>> t = count_tables([m], symmetries=False, progress=False)
>>> int(t.counts3x3.sum()), t.lam
(16, 0.16666666666666666)
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np
import torch

from ogm_ppl.priors.tables import PAIR_OFFSETS, PriorTables

__all__ = [
    "count_tables",
    "window_codes",
    "dihedral_maps",
    "dihedral_permutations",
    "permute_codes",
]


def _as_bool(a, what: str, index: int) -> np.ndarray:
    """``a`` as a bool array: bool, or numbers that are all 0 or 1; anything else (an image's 0..255, a map of
    probabilities) is refused, since ``bool()`` would call every non-zero value occupied."""
    arr = np.asarray(a)
    if arr.dtype == bool:
        return arr
    if arr.dtype.kind not in "biuf":
        raise ValueError(f"map {index}: {what} must be a bool array, got dtype {arr.dtype}")
    bad = (arr != 0) & (arr != 1)
    if bad.any():
        seen = np.unique(arr[bad])[:4]
        raise ValueError(
            f"map {index}: {what} must be bool (True = occupied) or 0/1, got values such as "
            f"{', '.join(f'{v:g}' for v in seen)} (dtype {arr.dtype}); for an image, threshold it (dark = occupied: "
            "image < 128) or read it with ogm_ppl.datasets.plan_files.load_plan_file"
        )
    return arr.astype(bool)


def _as_pair(item, index: int = 0) -> tuple[np.ndarray, np.ndarray | None]:
    """``(occupancy, known)`` from an array, a ``(occupancy, known)`` pair or an object with those attributes,
    each checked to be bool or 0/1 (:func:`_as_bool`)."""
    if hasattr(item, "occupancy"):
        return _as_bool(item.occupancy, "occupancy", index), _as_bool(item.known, "known", index)
    if isinstance(item, tuple):
        occ, known = item
        return _as_bool(occ, "occupancy", index), None if known is None else _as_bool(known, "known", index)
    return _as_bool(item, "the map", index), None


def dihedral_maps(m: torch.Tensor, symmetries: bool = True) -> list[torch.Tensor]:
    """The 8 flips/rotations of a 2D tensor (``rot90(m, k)`` for k = 0..3, then the same after a left-right flip);
    just ``[m]`` when ``symmetries`` is False."""
    if not symmetries:
        return [m]
    out = [torch.rot90(m, k, (0, 1)) for k in range(4)]
    f = torch.flip(m, (1,))
    return out + [torch.rot90(f, k, (0, 1)) for k in range(4)]


def dihedral_permutations(size: int) -> np.ndarray:
    """``8 x size**2`` index arrays: variant ``k`` of a ``size x size`` window ``w`` is
    ``w.ravel()[perm[k]].reshape(size, size)``, in the order of :func:`dihedral_maps`."""
    idx = torch.arange(size * size).reshape(size, size)
    return np.stack([t.reshape(-1).numpy() for t in dihedral_maps(idx)])


def permute_codes(codes: torch.Tensor, perm) -> torch.Tensor:
    """Codes of the permuted windows: bit ``j`` of the result is bit ``perm[j]`` of ``codes``."""
    out = torch.zeros_like(codes)
    for j, i in enumerate(np.asarray(perm).tolist()):
        out |= ((codes >> i) & 1) << j
    return out


def _codes(m: torch.Tensor, h: int, w: int, bits: int = 1) -> torch.Tensor:
    """``(H - h + 1) x (W - w + 1)`` int32 codes of all ``h x w`` windows (row-major bits, little-endian).

    ``m`` holds 0/1 cells, or (``bits > 1``) codes of ``bits`` bits each; then the windows' codes are
    concatenated, which builds a 5 x 5 code from five 1 x 5 row codes in 10 shifts instead of 25.
    """
    H, W = m.shape
    oh, ow = H - h + 1, W - w + 1
    out = torch.zeros((oh, ow), dtype=torch.int32)
    for dy in range(h):
        for dx in range(w):
            out |= m[dy : dy + oh, dx : dx + ow] << ((dy * w + dx) * bits)
    return out


def _valid(unknown: torch.Tensor | None, h: int, w: int) -> torch.Tensor | None:
    """Mask of windows with no unknown cell (integral image of the unknown mask); ``None`` when all known."""
    if unknown is None:
        return None
    s = torch.nn.functional.pad(unknown.to(torch.int64).cumsum(0).cumsum(1), (1, 0, 1, 0))
    H, W = unknown.shape
    oh, ow = H - h + 1, W - w + 1
    n = s[h : h + oh, w : w + ow] - s[:oh, w : w + ow] - s[h : h + oh, :ow] + s[:oh, :ow]
    return n == 0


def window_codes(occupancy, known=None, shape: tuple[int, int] = (3, 3)) -> torch.Tensor:
    """Flat int64 codes of every ``h x w`` window lying wholly on known cells (row-major window order).

    >>> window_codes(np.eye(3, dtype=bool)).tolist()   # cells 0, 4, 8 occupied
    [273]
    """
    occ = torch.as_tensor(np.asarray(occupancy, dtype=bool)).to(torch.int32)
    h, w = shape
    if occ.shape[0] < h or occ.shape[1] < w:
        return torch.zeros(0, dtype=torch.int64)
    codes = _codes(occ, h, w)
    unknown = None if known is None else ~torch.as_tensor(np.asarray(known, dtype=bool))
    valid = _valid(unknown, h, w)
    codes = codes.reshape(-1) if valid is None else codes[valid]
    return codes.long()


class _Counter:
    """Running counts; one :meth:`add` per map."""

    def __init__(self, symmetries: bool, line_length: int, max_run: int):
        self.sym = symmetries
        self.L = line_length
        self.R = max_run
        self.cells = torch.zeros(2, dtype=torch.int64)
        self.c3 = torch.zeros(512, dtype=torch.int64)
        self.c5_codes = torch.zeros(0, dtype=torch.int64)
        self.c5_counts = torch.zeros(0, dtype=torch.int64)
        self.pairs = torch.zeros((4, 2, 2), dtype=torch.int64)
        self.lines = torch.zeros(2**line_length, dtype=torch.int64)
        self.runs = torch.zeros((2, max_run + 1), dtype=torch.int64)
        self.perm3 = dihedral_permutations(3) if symmetries else np.arange(9)[None]
        self.perm5 = dihedral_permutations(5) if symmetries else np.arange(25)[None]
        self.base3 = torch.arange(512, dtype=torch.int64)
        self.reverse = permute_codes(torch.arange(2**line_length, dtype=torch.int64), np.arange(line_length)[::-1])

    def add(self, occ_np: np.ndarray, known_np: np.ndarray | None) -> None:
        occ = torch.as_tensor(occ_np).to(torch.int32)
        if known_np is not None and known_np.all():
            known_np = None
        k = None if known_np is None else torch.as_tensor(known_np)
        unknown = None if k is None else ~k
        if occ.shape[0] >= 3 and occ.shape[1] >= 3:
            self._windows(occ, unknown)
        # The cheap statistics are counted on the map itself and symmetrised in closed form; the tests check
        # that this equals counting the 8 transformed maps.
        g = 8 if self.sym else 1
        self.cells += g * (
            torch.bincount(occ.reshape(-1).long(), minlength=2)
            if k is None
            else torch.bincount(occ[k].long(), minlength=2)
        )
        self.runs += g * self._runs(occ, k)
        pairs = self._pairs(occ, k)
        lines = self._lines(occ, k)
        if self.sym:
            pt = pairs + pairs.transpose(1, 2)
            axial, diagonal = 2 * (pt[0] + pt[1]), 2 * (pt[2] + pt[3])
            pairs = torch.stack([axial, axial, diagonal, diagonal])
            both = lines[0] + lines[1]
            lines = 4 * (both + both[self.reverse])
        else:
            lines = lines[0] + lines[1]
        self.pairs += pairs
        self.lines += lines

    # -- windows: count once, symmetrise by permuting the bits of the distinct codes ----------------------------
    def _windows(self, occ, unknown):
        rows3 = _codes(occ, 1, 3)
        c3 = _codes(rows3, 3, 1, bits=3)
        v3 = _valid(unknown, 3, 3)
        c3 = c3.reshape(-1) if v3 is None else c3[v3]
        n3 = torch.bincount(c3.long(), minlength=512)
        for p in self.perm3:
            self.c3.index_add_(0, permute_codes(self.base3, p), n3)
        if occ.shape[0] < 5 or occ.shape[1] < 5:
            return
        c5 = _codes(_codes(occ, 1, 5), 5, 1, bits=5)
        v5 = _valid(unknown, 5, 5)
        c5 = c5.reshape(-1) if v5 is None else c5[v5]
        u, n = torch.unique_consecutive(torch.sort(c5.long()).values, return_counts=True)
        codes = torch.cat([self.c5_codes] + [permute_codes(u, p) for p in self.perm5])
        counts = torch.cat([self.c5_counts] + [n] * len(self.perm5))
        self.c5_codes, inv = torch.unique(codes, return_inverse=True)
        self.c5_counts = torch.zeros(self.c5_codes.numel(), dtype=torch.int64).index_add_(0, inv, counts)

    @staticmethod
    def _pairs(m, k) -> torch.Tensor:
        """``4 x 2 x 2`` joint counts for :data:`PAIR_OFFSETS` on one map."""
        H, W = m.shape
        out = torch.zeros((4, 2, 2), dtype=torch.int64)
        for i, (dr, dc) in enumerate(PAIR_OFFSETS):
            c0, c1 = max(0, -dc), W - max(0, dc)
            if H - dr <= 0 or c1 - c0 <= 0:
                continue
            ab = m[: H - dr, c0:c1] * 2 + m[dr:, c0 + dc : c1 + dc]
            if k is not None:
                ab = ab[k[: H - dr, c0:c1] & k[dr:, c0 + dc : c1 + dc]]
            out[i] = torch.bincount(ab.reshape(-1).long(), minlength=4).reshape(2, 2)
        return out

    def _lines(self, m, k) -> torch.Tensor:
        """``2 x 2**L``: line windows along rows (left to right) and along columns (top down)."""
        L = self.L
        out = torch.zeros((2, 2**L), dtype=torch.int64)
        for i, (mm, kk) in enumerate(((m, k), (m.T, None if k is None else k.T))):
            if mm.shape[1] < L:
                continue
            codes = _codes(mm, 1, L)
            valid = _valid(None if kk is None else ~kk, 1, L)
            codes = codes.reshape(-1) if valid is None else codes[valid]
            out[i] = torch.bincount(codes.long(), minlength=2**L)
        return out

    def _runs(self, m, k) -> torch.Tensor:
        """``2 x (R + 1)`` complete-run lengths along rows and columns (reversal does not change runs)."""
        R = self.R
        out = torch.zeros((2, R + 1), dtype=torch.int64)
        s = m.to(torch.int8)
        if k is not None:
            s = s.masked_fill(~k, 2)
        for ss in (s, s.T):
            f = torch.nn.functional.pad(ss.contiguous(), (0, 1), value=2).reshape(-1).numpy()
            starts = np.flatnonzero(np.r_[True, f[1:] != f[:-1]])
            vals = f[starts].astype(np.int64)
            lens = np.diff(np.r_[starts, f.size])
            prev = np.r_[2, vals[:-1]]
            nxt = np.r_[vals[1:], 2]
            ok = (vals < 2) & (prev == 1 - vals) & (nxt == 1 - vals)
            idx = vals[ok] * (R + 1) + np.minimum(lens[ok], R)
            out += torch.as_tensor(np.bincount(idx, minlength=2 * (R + 1)).reshape(2, R + 1))
        return out


def count_tables(
    maps: Iterable,
    *,
    symmetries: bool = True,
    line_length: int = 8,
    max_run: int = 64,
    min_count_5x5: int = 1,
    progress: bool = True,
    provenance: dict | None = None,
) -> PriorTables:
    """Count every table of :class:`~ogm_ppl.priors.tables.PriorTables` over a stream of maps.

    Args:
        maps: iterable of ``H x W`` bool arrays (all known), ``(occupancy, known)`` pairs, or objects with
            ``occupancy`` and ``known`` attributes (e.g. :class:`ogm_ppl.datasets.floorplans.FloorPlan`);
            ``True`` (or 1) = occupied / known. Numbers other than 0 and 1 (an image's 0..255) and an empty
            iterable are refused (``ValueError``). Processed one at a time (a generator keeps memory bounded).
        symmetries: add the 8 flips/rotations of every map (the thesis's "all eight permutations").
        line_length: ``L`` of the ``1 x L`` line table (``line_counts`` has ``2**L`` entries).
        max_run: run lengths ``>= max_run`` share the last bin of ``run_counts``.
        min_count_5x5: drop 5 x 5 codes seen fewer times (their total goes to ``truncated_mass``); 1 keeps all.
        progress: show a tqdm progress bar.
        provenance: extra JSON-able metadata stored with the tables (corpus, resolution, ...).

    Deterministic: the result depends only on the maps and the arguments.
    """
    if not 1 <= line_length <= 16:
        raise ValueError(f"count_tables: line_length must lie in 1..16, got {line_length}")
    if max_run < 1:
        raise ValueError(f"count_tables: max_run must be >= 1, got {max_run}")
    counter = _Counter(bool(symmetries), int(line_length), int(max_run))
    n_maps = 0
    threads = torch.get_num_threads()
    # many small ops: one thread is ~10x faster than two contending ones on a loaded 2-core machine
    torch.set_num_threads(1)
    try:
        from tqdm import tqdm  # (not tqdm.auto: a notebook without ipywidgets warns at import)

        for item in tqdm(maps, desc="counting windows", unit="map", disable=not progress):
            occ, known = _as_pair(item, n_maps)
            if occ.ndim != 2:
                raise ValueError(f"count_tables: map {n_maps} must be 2D, got shape {occ.shape}")
            if known is not None and known.shape != occ.shape:
                raise ValueError(f"count_tables: map {n_maps}: known {known.shape} != occupancy {occ.shape}")
            counter.add(occ, known)
            n_maps += 1
    finally:
        torch.set_num_threads(threads)
    if n_maps == 0:
        raise ValueError("count_tables: no maps to count (the iterable was empty)")
    codes, counts = counter.c5_codes, counter.c5_counts
    truncated = 0
    if min_count_5x5 > 1:
        keep = counts >= min_count_5x5
        truncated = int(counts[~keep].sum())
        codes, counts = codes[keep], counts[keep]
    prov = {
        "n_maps": n_maps,
        "symmetries": 8 if symmetries else 1,
        "line_length": int(line_length),
        "max_run": int(max_run),
        "min_count_5x5": int(min_count_5x5),
        "counted_by": "ogm_ppl.priors.learn.count_tables",
    }
    prov.update(provenance or {})
    return PriorTables(
        cell_counts=counter.cells.numpy(),
        counts3x3=counter.c3.numpy(),
        codes5x5=codes.numpy(),
        counts5x5=counts.numpy(),
        pair_counts=counter.pairs.numpy(),
        line_counts=counter.lines.numpy(),
        run_counts=counter.runs.numpy(),
        truncated_mass=truncated,
        provenance=prov,
    )
