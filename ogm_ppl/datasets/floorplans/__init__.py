r"""Real and synthetic floor-plan corpora rasterised to occupancy grids (training data for learned priors).

Six corpora live under ``<root>/`` (:func:`floorplan_root`: ``$OGM_PPL_FLOORPLANS``, else ``floorplans/`` of the
shared data folder ``$OGM_PPL_DATA``, else ``shared/data/floorplans`` beside a source checkout); see each corpus's
``PROVENANCE.md`` there. Three are images:

::

    ``"houseexpo"``  100 HouseExpo plans, PNG mode L, 255 = free (inside), 0 = wall *or outside*; 1 px = 1 cm.
    ``"ipa"``        IPA room-segmentation maps (Bormann et al. 2016): 0 = occupied, 255 = free, a grey background
                     (205, 180, 178, 153, ...) = unknown; mixed PIL modes and anti-aliasing; 0.05 m/px.
    ``"dungeon"``    DungeonMaps (synthetic): RGB(A) (127,127,127) = obstacle/outside, (195,195,194) = free,
                     (255,216,0) = robot start (free); no metric scale (1 px = 1 cell); read straight from the tar.gz.

and three are vector drawings, each read by a module of this package (its docstring says how, in full):

::

    ``"houseexpo-full"``  33,717 HouseExpo houses (synthetic, SUNCG) as outline polygons in metres, one
                          ``jsonl.gz`` read as a stream (:mod:`~ogm_ppl.datasets.floorplans.houseexpo_full`).
    ``"r2v"``             1,279 real Japanese homes (Raster-to-Vector): wall and opening lines in pixels, the scale
                          estimated per plan from its openings (:mod:`~ogm_ppl.datasets.floorplans.r2v`).
    ``"schools"``         50 floors of real schools: room polygons, walls and portals in pixels with a scale per
                          file (:mod:`~ogm_ppl.datasets.floorplans.schools`).

Every corpus is read at 0.05 m a cell by default (DungeonMaps: 1 px = 1 cell), the resolution of the shipped
priors and guides.

Rasterisation (:func:`load_plan`)
---------------------------------
1. Pixels are classified occupied / free / unknown. IPA: converted to grey; the background grey (the most common
   value on the image border, when it is neither black nor white) +-3 is unknown, the rest is thresholded at 128.
   ``houseexpo-full``: each polygon is rendered as HouseExpo renders it (1 cm pixels, inside free, the rest
   occupied), then as ``houseexpo``.
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

``r2v`` and ``schools`` are drawn straight onto the grid at ``resolution`` (:mod:`._vector`): rooms filled free,
walls drawn ``wall_thickness`` metres thick (default 0.15 m: 3 cells), openings cut from them, the rest outside
(unknown); then steps 3 and 5 (``wall_cells`` does not apply: the walls are drawn, not inferred).

Splits and exclusions
---------------------
Each plan belongs to a *building* (IPA variants ``_furnitures``/``_trashbins``/``_scan`` and the drawn/scanned
versions of one building share it; a school's floors share it; an R2V listing is one home). The split is fixed
by building: ``test`` if ``int(sha256("<corpus>:<building>")[:8], 16) % 5 == 0``, else ``train`` (about 80/20);
DungeonMaps keeps its own ``train/``/``test/`` directories, R2V the paper's ``train``/``val``/``test`` lists
(the hash for the listings in none), and ``houseexpo-full`` hashes with ``houseexpo``'s salt, so that a house in
both corpora is on the same side in both (:data:`BUILDING_NAMESPACE`; the leakage checks of
:mod:`ogm_ppl.calibration.leakage` compare their buildings). :func:`split_rule` states each corpus's rule.
:data:`REAL_LOG_BUILDINGS` names the IPA plans of buildings whose real logs are used for evaluation (Intel,
Freiburg 079/101/52); :func:`training_plans` leaves them out by default.

>>> names = training_plans("ipa")
>>> any("intel" in n.lower() or "freiburg" in n.lower() for n in names)
False
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterable, Iterator
from fnmatch import fnmatchcase

import numpy as np

from ogm_ppl.datasets.floorplans import houseexpo_full, r2v, schools
from ogm_ppl.datasets.floorplans._core import (
    CorpusNotFoundError,
    FloorPlan,
    PlanFormatError,
    finish,
    floorplan_root,
    hash_split,
    rasterise,
)
from ogm_ppl.datasets.floorplans.images import (
    dungeon_bytes,
    dungeon_pixels,
    list_image_plans,
    open_image,
    plan_image_path,
    plan_pixels,
)

__all__ = [
    "BUILDING_NAMESPACE",
    "CORPORA",
    "CorpusNotFoundError",
    "DEFAULT_RESOLUTION",
    "FloorPlan",
    "PlanFormatError",
    "REAL_LOG_BUILDINGS",
    "SPLITS",
    "WALL_THICKNESS",
    "building_namespace",
    "floorplan_root",
    "list_plans",
    "building_of",
    "split_of",
    "split_rule",
    "excluded",
    "training_plans",
    "sample_indices",
    "heldout_plans",
    "validation_plans",
    "load_plan",
    "iter_plans",
    "plan_from_outline",
    "plan_image_path",
    "rasterise",
]

CORPORA: tuple[str, ...] = ("houseexpo", "ipa", "dungeon", "houseexpo-full", "r2v", "schools")
#: metres per pixel of the corpora read as pixels (``None``: no metric scale); the vector corpora have none
NATIVE_RESOLUTION: dict[str, float | None] = {"houseexpo": 0.01, "ipa": 0.05, "dungeon": None, "houseexpo-full": 0.01}
DEFAULT_RESOLUTION: dict[str, float | None] = {
    "houseexpo": 0.05,
    "ipa": 0.05,
    "dungeon": None,
    "houseexpo-full": 0.05,
    "r2v": 0.05,
    "schools": 0.05,
}
#: metres of the walls drawn in the corpora whose walls are lines (default of ``wall_thickness``)
WALL_THICKNESS: dict[str, float] = {"r2v": r2v.WALL_THICKNESS, "schools": schools.WALL_THICKNESS}
#: the split names a plan can have (``val``: R2V's validation list; neither trained on nor tested by default)
SPLITS: tuple[str, ...] = ("train", "val", "test")
#: corpora that hold plans of another corpus's buildings under the same building names -> that corpus
BUILDING_NAMESPACE: dict[str, str] = {"houseexpo-full": "houseexpo"}
_VECTOR = ("r2v", "schools")

#: Real logs used for evaluation -> glob patterns (case-sensitive, on IPA plan names) of the same building.
#: MIT Stata (Section 6.2.2) has no plan in these corpora.
REAL_LOG_BUILDINGS: dict[str, tuple[str, ...]] = {
    "intel": ("intel_map*", "lab_intel*"),
    "freiburg079": ("Freiburg79*", "freiburg_building79*"),
    "freiburg101": ("Freiburg101*", "freiburg_building101*"),
    "freiburg052": ("Freiburg52*", "freiburg_building52*"),
    "mit_stata": (),
}


def _check_corpus(corpus: str) -> None:
    if corpus not in CORPORA:
        raise ValueError(f"unknown floor-plan corpus {corpus!r}; expected one of {CORPORA}")


def building_namespace(corpus: str) -> str:
    """The corpus whose building names ``corpus``'s plans use (itself but for :data:`BUILDING_NAMESPACE`): two
    corpora of one namespace hold plans of the same buildings, which a leakage check must compare."""
    return BUILDING_NAMESPACE.get(corpus, corpus)


def list_plans(corpus: str, root=None) -> list[str]:
    """All plan names of a corpus, sorted (natural order). IPA's ``*_gt_segmentation`` images are not maps and
    are left out. ``houseexpo-full``: the house ids, read from the file's lines without parsing polygons."""
    _check_corpus(corpus)
    if corpus == "houseexpo-full":
        return houseexpo_full.list_ids(root)
    if corpus == "r2v":
        return r2v.list_names(root)
    if corpus == "schools":
        return schools.list_names(root)
    return list_image_plans(corpus, root)


def building_of(corpus: str, name: str) -> str:
    """The building a plan shows (IPA: lower case, without ``_furnitures``/``_trashbins``/``_scan``;
    ``freiburg_building79``/``Freiburg79_scan`` -> ``freiburg79``; ``intel_map``/``lab_intel`` -> ``intel``;
    R2V: the listing; schools: :func:`~ogm_ppl.datasets.floorplans.schools.building_of`; else the name)."""
    _check_corpus(corpus)
    if corpus == "r2v":
        return r2v.building_of(name)
    if corpus == "schools":
        return schools.building_of(name)
    if corpus != "ipa":
        return name
    b = name.lower()
    for suffix in ("_furnitures", "_trashbins", "_scan"):
        b = b.replace(suffix, "")
    b = re.sub(r"^freiburg_building(\d+)$", r"freiburg\1", b)
    if b in ("intel_map", "lab_intel"):
        b = "intel"
    return b


def split_of(corpus: str, name: str, root=None) -> str:
    """``"train"``, ``"test"`` or (R2V) ``"val"``, fixed by the plan's building (:func:`split_rule`)."""
    _check_corpus(corpus)
    if corpus == "dungeon":
        return name.split("/", 1)[0]
    if corpus == "r2v":
        return r2v.split_of(name, root)
    return hash_split(building_namespace(corpus), building_of(corpus, name))


def split_rule(corpus: str) -> str:
    """How a corpus's split is fixed, in words (recorded with the statistics of :mod:`.stats`)."""
    _check_corpus(corpus)
    rule = "test if int(sha256('{salt}:<building>')[:8], 16) % 5 == 0, else train"
    if corpus == "dungeon":
        return "the archive's own train/ and test/ folders"
    if corpus == "r2v":
        return (
            f"the paper's lists ({r2v.SPLITS_DIR}/train|val|test.txt; a listing in several takes test, then val); "
            "a listing in none: " + rule.format(salt=r2v.SPLIT_SALT)
        )
    return rule.format(salt=building_namespace(corpus)) + " (by building)"


def excluded(name: str, exclude_buildings: Iterable[str] = tuple(REAL_LOG_BUILDINGS)) -> bool:
    """Whether ``name`` matches a pattern of one of the ``exclude_buildings`` (keys of :data:`REAL_LOG_BUILDINGS`)."""
    for key in exclude_buildings:
        if key not in REAL_LOG_BUILDINGS:
            raise KeyError(f"unknown real-log building {key!r}; expected one of {tuple(REAL_LOG_BUILDINGS)}")
        if any(fnmatchcase(name, pat) for pat in REAL_LOG_BUILDINGS[key]):
            return True
    return False


def _plans(corpus, split, exclude_buildings, limit, root) -> list[str]:
    names = [
        n for n in list_plans(corpus, root) if split_of(corpus, n, root) == split and not excluded(n, exclude_buildings)
    ]
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


def sample_indices(n: int, k: int, seed: int) -> list[int]:
    """``k`` of ``range(n)`` drawn without replacement, ascending: the first ``k`` of the permutation
    ``numpy.random.default_rng(seed).permutation(n)``, so that a smaller sample of the same seed is a subset of a
    larger one (the random subsets of training plans that priors are fitted on, ``--sample``)."""
    import numpy as np

    if not 0 <= k <= n:
        raise ValueError(f"a sample of {k} from {n} plans: it must be at most {n}")
    return sorted(int(i) for i in np.random.default_rng(seed).permutation(n)[:k])


def heldout_plans(corpus: str, exclude_buildings: Iterable[str] = (), limit: int | None = None, root=None) -> list[str]:
    """Names of the held-out plans (nothing excluded by default)."""
    return _plans(corpus, "test", tuple(exclude_buildings), limit, root)


def validation_plans(corpus: str, limit: int | None = None, root=None) -> list[str]:
    """Names of the validation plans (R2V's ``val`` list; empty for the other corpora)."""
    return _plans(corpus, "val", (), limit, root)


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


def _metres(value, what: str, corpus: str) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        v = math.nan
    if not (math.isfinite(v) and v > 0):
        raise ValueError(f"{corpus}: {what} must be a positive number of metres, got {value!r}")
    return v


def _plan(corpus, name, occ, known, resolution, root) -> FloorPlan:
    return FloorPlan(
        name=name,
        corpus=corpus,
        occupancy=occ,
        known=known,
        resolution=None if resolution is None else float(resolution),
        building=building_of(corpus, name),
        split=split_of(corpus, name, root),
    )


def load_plan(
    corpus: str,
    name: str,
    resolution: float | str | None = "default",
    margin: int | None = 20,
    wall_cells: int = 2,
    outside: str = "occupied",
    root=None,
    *,
    wall_thickness: float | None = None,
) -> FloorPlan:
    """Read and rasterise one plan (see the module docstring).

    Args:
        corpus: a name of :data:`CORPORA`.
        name: a name from :func:`list_plans`.
        resolution: metres per cell: for HouseExpo (either corpus) and IPA an integer multiple of the pixel size
            (0.01, 0.05), for R2V and schools any; ``"default"`` = 0.05 m, or 1 px = 1 cell for DungeonMaps (no
            metric scale: pass None).
        margin: cells kept around the free space's bounding box (``None``: keep the whole image).
        wall_cells: non-free cells within this many cells of free space are walls, not outside (the corpora read
            as pixels).
        outside: ``"occupied"`` (thesis-like solid exterior) or ``"unknown"`` (exterior excluded from counting).
        wall_thickness: metres of the walls drawn in R2V and schools (default :data:`WALL_THICKNESS`).

    Raises:
        KeyError: no such plan. PlanFormatError (a ``ValueError``): a malformed file, naming it, the line and
        the field. CorpusNotFoundError: the corpus is not there.
    """
    return next(
        iter_plans(corpus, [name], resolution, margin, wall_cells, outside, root, wall_thickness=wall_thickness)
    )


def iter_plans(
    corpus: str,
    names: Iterable[str] | None = None,
    resolution: float | str | None = "default",
    margin: int | None = 20,
    wall_cells: int = 2,
    outside: str = "occupied",
    root=None,
    *,
    wall_thickness: float | None = None,
) -> Iterator[FloorPlan]:
    """Yield the named plans (default: :func:`training_plans`) one at a time, in the given order (arguments as
    :func:`load_plan`).

    DungeonMaps are read in one pass over the archive (their compressed PNGs, a few kB each, are held in memory);
    ``houseexpo-full`` in one pass over its file, parsing only the lines asked for.
    """
    _check_corpus(corpus)
    names = training_plans(corpus, root=root) if names is None else list(names)
    if resolution == "default":
        resolution = DEFAULT_RESOLUTION[corpus]
    if corpus in _VECTOR:
        res = _metres(resolution, "resolution", corpus)
        thick = _metres(WALL_THICKNESS[corpus] if wall_thickness is None else wall_thickness, "wall_thickness", corpus)
        for n in names:
            occ_c, free_c = _vector_cells(corpus, n, res, thick, root)
            yield _plan(corpus, n, *finish(occ_c, free_c, margin, outside), res, root)
        return
    f = _factor(corpus, resolution)
    if corpus == "houseexpo-full":
        for n, verts in houseexpo_full.records(names, root):
            yield plan_from_outline(n, verts, resolution, margin, wall_cells, outside, root)
        return
    if corpus == "dungeon":
        raw = dungeon_bytes(names, root)
        for n in names:
            data, where = raw[n]
            occ_px, free_px = dungeon_pixels(open_image(data, where), where)
            yield _plan(corpus, n, *rasterise(occ_px, free_px, f, margin, wall_cells, outside), resolution, root)
        return
    for n in names:
        occ_px, free_px = plan_pixels(corpus, n, root)
        yield _plan(corpus, n, *rasterise(occ_px, free_px, f, margin, wall_cells, outside), resolution, root)


def plan_from_outline(
    name: str,
    verts: np.ndarray,
    resolution: float | str | None = "default",
    margin: int | None = 20,
    wall_cells: int = 2,
    outside: str = "occupied",
    root=None,
) -> FloorPlan:
    """The ``houseexpo-full`` plan ``name`` from its outline ``verts`` (``V x 2`` metres, as
    :func:`~ogm_ppl.datasets.floorplans.houseexpo_full.records` yields it), rasterised as :func:`load_plan`
    does: to read many plans without a pass over the corpus file for each."""
    corpus = "houseexpo-full"
    if resolution == "default":
        resolution = DEFAULT_RESOLUTION[corpus]
    f = _factor(corpus, resolution)
    occ_px, free_px = houseexpo_full.checked_pixels(name, verts, root)
    return _plan(corpus, name, *rasterise(occ_px, free_px, f, margin, wall_cells, outside), resolution, root)


def _vector_cells(corpus: str, name: str, resolution: float, thickness: float, root) -> tuple[np.ndarray, np.ndarray]:
    """``(occupied, free)`` cells of an R2V or schools plan, uncropped (the rest: outside)."""
    if corpus == "r2v":
        path = r2v.plan_path(name, root)
        plan = r2v.read_plan(path)
        return r2v.plan_cells(plan, r2v.estimate_scale(plan), resolution, thickness, path)
    path = schools.plan_path(name, root)
    return schools.plan_cells(schools.read_plan(path), resolution, thickness, path)
