r"""Real and synthetic floor-plan corpora rasterised to occupancy grids (training data for learned priors).

Three corpora live under ``<root>/`` (:func:`floorplan_root`: ``$OGM_PPL_FLOORPLANS``, else ``floorplans/`` of the
shared data folder ``$OGM_PPL_DATA``, else ``shared/data/floorplans`` beside a source checkout); see each corpus's
``PROVENANCE.md`` there:

::

    ``"houseexpo"``  100 HouseExpo plans, PNG mode L, 255 = free (inside), 0 = wall *or outside*; 1 px = 1 cm.
    ``"ipa"``        IPA room-segmentation maps (Bormann et al. 2016): 0 = occupied, 255 = free, a grey background
                     (205, 180, 178, 153, ...) = unknown; mixed PIL modes and anti-aliasing; 0.05 m/px.
    ``"dungeon"``    DungeonMaps (synthetic): RGB(A) (127,127,127) = obstacle/outside, (195,195,194) = free,
                     (255,216,0) = robot start (free); no metric scale (1 px = 1 cell); read straight from the tar.gz.

Rasterisation (:func:`load_plan`)
---------------------------------
1. Pixels are classified occupied / free / unknown. IPA: converted to grey; the background grey (the most common
   value on the image border, when it is neither black nor white) +-3 is unknown, the rest is thresholded at 128.
2. Downsampled by an integer factor to ``resolution``: a cell is occupied if any of its pixels is occupied, else
   free if any pixel is free, else unknown (thin walls survive).
3. Cropped to the bounding box of the free cells plus ``margin`` cells (default 20, the width of the occupied
   border of the thesis's maps, Fig. 5.9), padding with unknown where the image is smaller.
4. **Outside.** Non-free cells that are connected (8-neighbours, through non-free cells) to the edge of the
   cropped map and lie more than ``wall_cells`` cells (Chebyshev) from any free cell are *outside*, i.e. unknown:
   only wall pixels near free space count as walls (HouseExpo's PROVENANCE).
5. ``outside="occupied"`` (the default) turns every unknown cell into a known occupied cell, like the thesis's
   ground-truth maps, which have occupied exteriors; then every window is counted and the exterior is solid
   wall ``margin`` cells deep. ``outside="unknown"`` keeps them unknown (``known = False``): the learner then
   skips every window touching one, so exterior walls are seen only ``wall_cells`` deep.

Splits and exclusions
---------------------
Each plan belongs to a *building* (IPA variants ``_furnitures``/``_trashbins``/``_scan`` and the drawn/scanned
versions of one building share it). The split is fixed by building: ``test`` if
``int(sha256("<corpus>:<building>")[:8], 16) % 5 == 0``, else ``train`` (about 80/20); DungeonMaps keeps its
own ``train/``/``test/`` directories. :data:`REAL_LOG_BUILDINGS` names the IPA plans of buildings whose real logs
are used for evaluation (Intel, Freiburg 079/101/52); :func:`training_plans` leaves them out by default.

>>> names = training_plans("ipa")
>>> any("intel" in n.lower() or "freiburg" in n.lower() for n in names)
False
"""

from __future__ import annotations

import hashlib
import io
import os
import re
import tarfile
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass
from fnmatch import fnmatchcase
from functools import lru_cache
from pathlib import Path

import numpy as np

__all__ = [
    "CORPORA",
    "CorpusNotFoundError",
    "FloorPlan",
    "REAL_LOG_BUILDINGS",
    "floorplan_root",
    "list_plans",
    "building_of",
    "split_of",
    "excluded",
    "training_plans",
    "heldout_plans",
    "load_plan",
    "iter_plans",
    "rasterise",
]

CORPORA: tuple[str, ...] = ("houseexpo", "ipa", "dungeon")
NATIVE_RESOLUTION = {"houseexpo": 0.01, "ipa": 0.05, "dungeon": None}
DEFAULT_RESOLUTION = {"houseexpo": 0.05, "ipa": 0.05, "dungeon": None}
_DUNGEON_TAR = "dungeonmaps-synthetic/DungeonMaps_subset_train2000_test500.tar.gz"
_HOUSEEXPO_DIR = "houseexpo-subset100/png"
_IPA_DIR = "ipa-room-segmentation-maps/test_maps"

#: Real logs used for evaluation -> glob patterns (case-sensitive, on IPA plan names) of the same building.
#: MIT Stata (Section 6.2.2) has no plan in these corpora.
REAL_LOG_BUILDINGS: dict[str, tuple[str, ...]] = {
    "intel": ("intel_map*", "lab_intel*"),
    "freiburg079": ("Freiburg79*", "freiburg_building79*"),
    "freiburg101": ("Freiburg101*", "freiburg_building101*"),
    "freiburg052": ("Freiburg52*", "freiburg_building52*"),
    "mit_stata": (),
}


@dataclass(frozen=True, eq=False)
class FloorPlan:
    """One rasterised plan. ``occupancy``, ``known``: ``H x W`` bool (``True`` = occupied / known).

    ``resolution`` is metres per cell, or ``None`` where the corpus has no metric scale (DungeonMaps).
    Where ``known`` is False the occupancy value is meaningless (set to False).
    """

    name: str
    corpus: str
    occupancy: np.ndarray
    known: np.ndarray
    resolution: float | None
    building: str
    split: str

    @property
    def shape(self) -> tuple[int, int]:
        return tuple(self.occupancy.shape)

    @property
    def occupied_fraction(self) -> float:
        """Share of known cells that are occupied."""
        return float(self.occupancy[self.known].mean()) if self.known.any() else float("nan")


# -- locating files --------------------------------------------------------------------------------------------
def floorplan_root(root=None) -> Path:
    """``root``, else ``$OGM_PPL_FLOORPLANS``, else ``$OGM_PPL_DATA/floorplans`` (the shared data folder), else
    ``shared/data/floorplans`` beside the repository of a source checkout. The folder need not exist (a plan file
    is then compared with no corpus); reading a corpus from a missing folder raises :class:`CorpusNotFoundError`."""
    if root is not None:
        return Path(root)
    env = os.environ.get("OGM_PPL_FLOORPLANS")
    if env:
        return Path(env)
    data = os.environ.get("OGM_PPL_DATA")
    if data:
        return Path(data) / "floorplans"
    return Path(__file__).resolve().parents[3] / "shared" / "data" / "floorplans"


class CorpusNotFoundError(FileNotFoundError):
    """A floor-plan corpus is not where :func:`floorplan_root` looks; the message says where it looked and how to
    point the library at the data."""


def _corpus_path(path: Path, corpus: str) -> Path:
    """``path`` (a corpus's folder or archive) if it exists, else :class:`CorpusNotFoundError`."""
    if not path.exists():
        raise CorpusNotFoundError(
            f"{path}: the {corpus} floor-plan corpus is not there; set $OGM_PPL_DATA to the shared data folder "
            "(the one holding floorplans/) or $OGM_PPL_FLOORPLANS to the corpora's folder"
        )
    return path


def _check_corpus(corpus: str) -> None:
    if corpus not in CORPORA:
        raise ValueError(f"unknown floor-plan corpus {corpus!r}; expected one of {CORPORA}")


def _natural_key(s: str):
    return [int(t) if t.isdigit() else t for t in re.split(r"(\d+)", s)]


@lru_cache(maxsize=8)
def _dungeon_members(tar_path: str) -> dict[str, str]:
    """Plan name (``train/762``, ``test/img_6296``) -> tar member name."""
    try:
        with tarfile.open(tar_path, "r:gz") as tf:
            names = tf.getnames()
    except (OSError, tarfile.TarError) as e:
        raise ValueError(f"{tar_path}: unreadable DungeonMaps archive ({e})") from e
    out = {}
    for m in names:
        parts = m.split("/")
        if len(parts) == 3 and parts[1] in ("train", "test") and parts[2].endswith(".png"):
            out[f"{parts[1]}/{parts[2][:-4]}"] = m
    return out


def list_plans(corpus: str, root=None) -> list[str]:
    """All plan names of a corpus, sorted (natural order). IPA's ``*_gt_segmentation`` images are not maps and
    are left out."""
    _check_corpus(corpus)
    base = floorplan_root(root)
    if corpus == "houseexpo":
        d = _corpus_path(base / _HOUSEEXPO_DIR, corpus)
        return sorted((p.stem for p in d.glob("*.png")), key=_natural_key)
    if corpus == "ipa":
        d = _corpus_path(base / _IPA_DIR, corpus)
        files = [p for p in d.iterdir() if p.suffix in (".png", ".pgm") and "_gt_segmentation" not in p.stem]
        return sorted((p.stem for p in files), key=_natural_key)
    return sorted(_dungeon_members(str(_corpus_path(base / _DUNGEON_TAR, corpus))), key=_natural_key)


def building_of(corpus: str, name: str) -> str:
    """The building a plan shows (IPA: lower case, without ``_furnitures``/``_trashbins``/``_scan``;
    ``freiburg_building79``/``Freiburg79_scan`` -> ``freiburg79``; ``intel_map``/``lab_intel`` -> ``intel``)."""
    _check_corpus(corpus)
    if corpus != "ipa":
        return name
    b = name.lower()
    for suffix in ("_furnitures", "_trashbins", "_scan"):
        b = b.replace(suffix, "")
    b = re.sub(r"^freiburg_building(\d+)$", r"freiburg\1", b)
    if b in ("intel_map", "lab_intel"):
        b = "intel"
    return b


def split_of(corpus: str, name: str) -> str:
    """``"train"`` or ``"test"`` (fixed; see the module docstring)."""
    _check_corpus(corpus)
    if corpus == "dungeon":
        return name.split("/", 1)[0]
    h = int(hashlib.sha256(f"{corpus}:{building_of(corpus, name)}".encode()).hexdigest()[:8], 16)
    return "test" if h % 5 == 0 else "train"


def excluded(name: str, exclude_buildings: Iterable[str] = tuple(REAL_LOG_BUILDINGS)) -> bool:
    """Whether ``name`` matches a pattern of one of the ``exclude_buildings`` (keys of :data:`REAL_LOG_BUILDINGS`)."""
    for key in exclude_buildings:
        if key not in REAL_LOG_BUILDINGS:
            raise KeyError(f"unknown real-log building {key!r}; expected one of {tuple(REAL_LOG_BUILDINGS)}")
        if any(fnmatchcase(name, pat) for pat in REAL_LOG_BUILDINGS[key]):
            return True
    return False


def _plans(corpus, split, exclude_buildings, limit, root) -> list[str]:
    names = [n for n in list_plans(corpus, root) if split_of(corpus, n) == split and not excluded(n, exclude_buildings)]
    return names if limit is None else names[: int(limit)]


def training_plans(
    corpus: str,
    exclude_buildings: Iterable[str] = tuple(REAL_LOG_BUILDINGS),
    limit: int | None = None,
    root=None,
) -> list[str]:
    """Names of the training plans, without the buildings of real evaluation logs (all of them by default);
    ``limit`` keeps the first ``limit`` in natural order."""
    return _plans(corpus, "train", tuple(exclude_buildings), limit, root)


def heldout_plans(corpus: str, exclude_buildings: Iterable[str] = (), limit: int | None = None, root=None) -> list[str]:
    """Names of the held-out plans (nothing excluded by default)."""
    return _plans(corpus, "test", tuple(exclude_buildings), limit, root)


# -- reading pixels --------------------------------------------------------------------------------------------
def _open_image(data_or_path, where: str):
    from PIL import Image

    try:
        im = Image.open(io.BytesIO(data_or_path) if isinstance(data_or_path, bytes) else data_or_path)
        im.load()
    except Exception as e:
        raise ValueError(f"{where}: unreadable image ({type(e).__name__}: {e})") from e
    return im


def _classify_binary(im) -> tuple[np.ndarray, np.ndarray]:
    """HouseExpo: grey >= 128 free, else occupied (wall or outside)."""
    g = np.asarray(im.convert("L"))
    free = g >= 128
    return ~free, free


def _classify_ipa(im) -> tuple[np.ndarray, np.ndarray]:
    g = np.asarray(im.convert("L")).astype(np.int16)
    edge = np.concatenate([g[0], g[-1], g[:, 0], g[:, -1]])
    bg = int(np.bincount(edge).argmax())
    unknown = np.zeros(g.shape, dtype=bool)
    if 20 < bg < 235:
        unknown = np.abs(g - bg) <= 3
    occ = (g < 128) & ~unknown
    free = (g >= 128) & ~unknown
    return occ, free


_DUNGEON_COLOURS = {(127, 127, 127): "occ", (195, 195, 194): "free", (255, 216, 0): "free"}


def _classify_dungeon(im, where: str) -> tuple[np.ndarray, np.ndarray]:
    rgb = np.asarray(im.convert("RGB")).astype(np.int32)
    key = (rgb[..., 0] << 16) | (rgb[..., 1] << 8) | rgb[..., 2]
    occ = key == (127 << 16 | 127 << 8 | 127)
    free = (key == (195 << 16 | 195 << 8 | 194)) | (key == (255 << 16 | 216 << 8 | 0))
    if not (occ | free).all():
        bad = np.unique(rgb[~(occ | free)].reshape(-1, 3), axis=0)[:3].tolist()
        raise ValueError(f"{where}: unexpected colours {bad} (DungeonMaps has exactly {list(_DUNGEON_COLOURS)})")
    return occ, free


def plan_image_path(corpus: str, name: str, root=None) -> Path:
    """The image file of a HouseExpo or IPA plan (DungeonMaps live inside one archive: ``KeyError``)."""
    base = floorplan_root(root)
    if corpus == "houseexpo":
        path = base / _HOUSEEXPO_DIR / f"{name}.png"
        if not path.is_file():
            raise KeyError(f"no HouseExpo plan {name!r} under {path.parent}")
        return path
    if corpus == "ipa":
        d = base / _IPA_DIR
        found = next((d / f"{name}{ext}" for ext in (".png", ".pgm") if (d / f"{name}{ext}").is_file()), None)
        if found is None:
            raise KeyError(f"no IPA plan {name!r} under {d}")
        return found
    raise KeyError(f"{corpus} plans are not image files")


def _pixels(corpus: str, name: str, root) -> tuple[np.ndarray, np.ndarray]:
    if corpus in ("houseexpo", "ipa"):
        path = plan_image_path(corpus, name, root)
        classify = _classify_binary if corpus == "houseexpo" else _classify_ipa
        return classify(_open_image(path, str(path)))
    data, where = _dungeon_bytes([name], root)[name]
    return _classify_dungeon(_open_image(data, where), where)


def _dungeon_bytes(names: Sequence[str], root) -> dict[str, tuple[bytes, str]]:
    """The PNG bytes of the named DungeonMaps, read in one pass over the archive (no extraction to disk)."""
    tar_path = str(_corpus_path(floorplan_root(root) / _DUNGEON_TAR, "dungeon"))
    members = _dungeon_members(tar_path)
    wanted = {}
    for n in names:
        if n not in members:
            raise KeyError(f"no DungeonMaps plan {n!r} in {tar_path}")
        wanted[members[n]] = n
    out = {}
    with tarfile.open(tar_path, "r:gz") as tf:
        for info in tf:
            if info.name in wanted:
                where = f"{tar_path}!{info.name}"
                f = tf.extractfile(info)
                if f is None:
                    raise ValueError(f"{where}: not a regular file")
                out[wanted[info.name]] = (f.read(), where)
                if len(out) == len(wanted):
                    break
    return out


# -- rasterising -----------------------------------------------------------------------------------------------
def _factor(corpus: str, resolution) -> int:
    native = NATIVE_RESOLUTION[corpus]
    if resolution is None or native is None:
        if resolution not in (None, 1, 1.0) and native is None:
            raise ValueError(f"{corpus} has no metric scale; pass resolution=None (1 px = 1 cell) or an int factor")
        return 1
    f = resolution / native
    if f < 1 - 1e-9 or abs(f - round(f)) > 1e-6:
        raise ValueError(
            f"resolution {resolution} must be an integer multiple of {corpus}'s {native} m/px (got factor {f:.4g})"
        )
    return round(f)


def _downsample(occ, free, f: int):
    if f == 1:
        return occ, free
    H, W = occ.shape
    h, w = -(-H // f), -(-W // f)
    pad = ((0, h * f - H), (0, w * f - W))
    o = np.pad(occ, pad).reshape(h, f, w, f).any((1, 3))
    fr = np.pad(free, pad).reshape(h, f, w, f).any((1, 3))
    return o, fr & ~o


def _crop(occ, free, margin):
    if margin is None or not free.any():
        return occ, free
    rows, cols = np.flatnonzero(free.any(1)), np.flatnonzero(free.any(0))
    r0, r1, c0, c1 = (
        rows[0] - margin,
        rows[-1] + 1 + margin,
        cols[0] - margin,
        cols[-1] + 1 + margin,
    )
    H, W = occ.shape
    pad = ((max(0, -r0), max(0, r1 - H)), (max(0, -c0), max(0, c1 - W)))
    occ, free = np.pad(occ, pad), np.pad(free, pad)
    r0, c0 = r0 + pad[0][0], c0 + pad[1][0]
    r1, c1 = r1 + pad[0][0], c1 + pad[1][0]
    return occ[r0:r1, c0:c1], free[r0:r1, c0:c1]


def _outside(occ, free, wall_cells: int) -> np.ndarray:
    """Non-free cells connected to the map's edge and more than ``wall_cells`` from free space."""
    from scipy import ndimage

    solid = ~free
    labels, _ = ndimage.label(solid, structure=np.ones((3, 3), dtype=bool))
    edge = np.unique(np.concatenate([labels[0], labels[-1], labels[:, 0], labels[:, -1]]))
    touching = np.isin(labels, edge[edge > 0])
    near = (
        ndimage.binary_dilation(free, structure=np.ones((3, 3), dtype=bool), iterations=wall_cells)
        if wall_cells > 0
        else free
    )
    return touching & ~near


def rasterise(
    occ_px: np.ndarray,
    free_px: np.ndarray,
    factor: int = 1,
    margin: int | None = 20,
    wall_cells: int = 2,
    outside: str = "occupied",
) -> tuple[np.ndarray, np.ndarray]:
    """Steps 2-5 of the module docstring on classified pixels -> ``(occupancy, known)``."""
    if outside not in ("occupied", "unknown"):
        raise ValueError(f"outside must be 'occupied' or 'unknown', got {outside!r}")
    occ, free = _downsample(np.asarray(occ_px, bool), np.asarray(free_px, bool) & ~np.asarray(occ_px, bool), factor)
    occ, free = _crop(occ, free, margin)
    unknown = ~(occ | free) | _outside(occ, free, wall_cells)
    if outside == "occupied":
        return ~free, np.ones(free.shape, dtype=bool)
    return occ & ~unknown, ~unknown


def load_plan(
    corpus: str,
    name: str,
    resolution: float | str | None = "default",
    margin: int | None = 20,
    wall_cells: int = 2,
    outside: str = "occupied",
    root=None,
) -> FloorPlan:
    """Read and rasterise one plan (see the module docstring).

    Args:
        corpus: ``"houseexpo"``, ``"ipa"`` or ``"dungeon"``.
        name: a name from :func:`list_plans`.
        resolution: metres per cell, an integer multiple of the corpus's pixel size (HouseExpo 0.01, IPA 0.05);
            ``"default"`` = 0.05 m (HouseExpo, IPA) or 1 px = 1 cell (DungeonMaps, no metric scale: pass None).
        margin: cells kept around the free space's bounding box (``None``: keep the whole image).
        wall_cells: non-free cells within this many cells of free space are walls, not outside.
        outside: ``"occupied"`` (thesis-like solid exterior) or ``"unknown"`` (exterior excluded from counting).
    """
    _check_corpus(corpus)
    if resolution == "default":
        resolution = DEFAULT_RESOLUTION[corpus]
    f = _factor(corpus, resolution)
    occ_px, free_px = _pixels(corpus, name, root)
    return _make(corpus, name, occ_px, free_px, f, resolution, margin, wall_cells, outside)


def _make(corpus, name, occ_px, free_px, f, resolution, margin, wall_cells, outside) -> FloorPlan:
    occ, known = rasterise(occ_px, free_px, f, margin, wall_cells, outside)
    return FloorPlan(
        name=name,
        corpus=corpus,
        occupancy=occ,
        known=known,
        resolution=None if resolution is None else float(resolution),
        building=building_of(corpus, name),
        split=split_of(corpus, name),
    )


def iter_plans(
    corpus: str,
    names: Iterable[str] | None = None,
    resolution: float | str | None = "default",
    margin: int | None = 20,
    wall_cells: int = 2,
    outside: str = "occupied",
    root=None,
) -> Iterator[FloorPlan]:
    """Yield the named plans (default: :func:`training_plans`) one at a time, in the given order.

    DungeonMaps are read in one pass over the archive (their compressed PNGs, a few kB each, are held in memory).
    """
    _check_corpus(corpus)
    names = training_plans(corpus, root=root) if names is None else list(names)
    if resolution == "default":
        resolution = DEFAULT_RESOLUTION[corpus]
    f = _factor(corpus, resolution)
    if corpus == "dungeon":
        raw = _dungeon_bytes(names, root)
        for n in names:
            data, where = raw[n]
            occ_px, free_px = _classify_dungeon(_open_image(data, where), where)
            yield _make(corpus, n, occ_px, free_px, f, resolution, margin, wall_cells, outside)
        return
    for n in names:
        yield load_plan(corpus, n, resolution, margin, wall_cells, outside, root)
