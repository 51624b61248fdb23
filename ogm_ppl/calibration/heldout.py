"""Held-out test maps for scoring priors and guides as predictors of what was not seen (thesis Section 5.2).

A test map is a ``window x window`` crop (:func:`choose_window`: the crop holding the most free cells next to
a wall) of a held-out plan of a floor-plan corpus (:func:`heldout_maps`: the corpus's held-out split, the
buildings of the real logs left out), of a generated map drawn from seeds no shipped table counted
(:func:`generated_windows`), or of a plan file of a building in no corpus (:func:`plan_file_maps`, refused when
it is a copy of a corpus plan). :mod:`ogm_ppl.calibration.leakage` checks a prior's or guide's training set
against them.
"""

from __future__ import annotations

import hashlib
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ogm_ppl.calibration.leakage import LeakageError
from ogm_ppl.datasets import floorplans as fp
from ogm_ppl.datasets.mapgen import KINDS as MAP_KINDS
from ogm_ppl.datasets.mapgen import generate_map
from ogm_ppl.datasets.plan_files import PlanFileError

__all__ = [
    "GENERATED_HELDOUT_SEED",
    "MIN_FREE_CELLS",
    "NoUsablePlanError",
    "PLAN_FILES_GUIDE",
    "PLAN_FILES_PRIORS",
    "TEST_CORPORA",
    "DEFAULT_TEST_CORPORA",
    "TestMap",
    "check_plan_files",
    "choose_window",
    "generated_seed",
    "generated_windows",
    "heldout_maps",
    "plan_digests",
    "plan_file_maps",
    "usable_windows",
]

#: the test corpora of the calibration protocol: generated maps and the held-out plans of each floor-plan corpus
TEST_CORPORA: tuple[str, ...] = ("generated", *fp.CORPORA)
#: the test corpora a run scores when none are named (the thesis's; the others are named with ``--test``)
DEFAULT_TEST_CORPORA: tuple[str, ...] = ("generated", "houseexpo", "ipa", "dungeon")
#: held-out generated map ``i`` is ``generate_map(KINDS[i % 4], seed=GENERATED_HELDOUT_SEED + i)``: a root seed
#: stream, never one of the spawned children ``SeedSequence(seed).spawn(n)`` the tables counted
GENERATED_HELDOUT_SEED = 50_000
#: a test window must hold at least this many known free cells
MIN_FREE_CELLS = 200


class NoUsablePlanError(ValueError):
    """No plan of the files given has a window with :data:`MIN_FREE_CELLS` known free cells."""


@dataclass(frozen=True)
class TestMap:
    """One held-out map: ``truth``, ``known`` ``H x W`` bool (True = occupied / known), its corpus and name
    (``plan@rROW,cCOL`` for a window of a larger plan), metres per cell."""

    corpus: str
    name: str
    plan: str
    truth: np.ndarray
    known: np.ndarray
    resolution: float


def choose_window(occupancy: np.ndarray, known: np.ndarray, window: int, stride: int = 4) -> tuple[int, int]:
    """Top-left corner of the ``window x window`` crop holding the most *wall-side* cells (known free cells
    with an occupied 4-neighbour), scanned with ``stride``; ``(0, 0)`` when the map is no larger.

    Summed-area table of the wall-side map ``w``: the count of a window at ``(r, c)`` is
    ``S[r+h, c+w] - S[r, c+w] - S[r+h, c] + S[r, c]``.
    """
    H, W = occupancy.shape
    h, w = min(window, H), min(window, W)
    free = known & ~occupancy
    occ = np.pad(occupancy & known, 1)
    side = free & (occ[:-2, 1:-1] | occ[2:, 1:-1] | occ[1:-1, :-2] | occ[1:-1, 2:])
    S = np.zeros((H + 1, W + 1), dtype=np.int64)
    S[1:, 1:] = side.cumsum(0).cumsum(1)
    rs = np.unique(np.r_[np.arange(0, H - h + 1, stride), H - h])
    cs = np.unique(np.r_[np.arange(0, W - w + 1, stride), W - w])
    R, C = np.meshgrid(rs, cs, indexing="ij")
    count = S[R + h, C + w] - S[R, C + w] - S[R + h, C] + S[R, C]
    i = np.unravel_index(int(np.argmax(count)), count.shape)
    return int(R[i]), int(C[i])


def _crop(corpus, plan, occupancy, known, resolution, window) -> TestMap:
    r0, c0 = choose_window(occupancy, known, window)
    h, w = min(window, occupancy.shape[0]), min(window, occupancy.shape[1])
    name = plan if (h, w) == occupancy.shape else f"{plan}@r{r0},c{c0}"
    sl = (slice(r0, r0 + h), slice(c0, c0 + w))
    return TestMap(corpus, name, plan, occupancy[sl].copy(), known[sl].copy(), resolution)


def generated_seed(i: int) -> int:
    """The integer seed of held-out generated map ``i``."""
    return GENERATED_HELDOUT_SEED + int(i)


def heldout_maps(corpus: str, n: int, window: int, generated_shape: int = 160) -> list[TestMap]:
    """The first ``n`` held-out maps of ``corpus`` (natural order of the held-out plans, real-log buildings
    left out; plans with fewer than 200 free cells in their window skipped), each cropped to ``window``.
    ``generated``: ``generate_map(KINDS[i % 4], (generated_shape,) * 2, seed=generated_seed(i))``."""
    if corpus == "generated":
        return generated_windows(n, generated_shape, window, GENERATED_HELDOUT_SEED)
    names = fp.heldout_plans(corpus, exclude_buildings=tuple(fp.REAL_LOG_BUILDINGS))
    return usable_windows(corpus, names, n, window)


def usable_windows(corpus: str, names: Sequence[str], n: int, window: int) -> list[TestMap]:
    """The first ``n`` plans of ``names`` (in order) whose chosen ``window`` holds at least 200 known free
    cells, each cropped to it (:func:`choose_window`); fewer when the names run out."""
    out: list[TestMap] = []
    if n <= 0:
        return out
    for p in fp.iter_plans(corpus, list(names)):  # one pass (houseexpo-full: over its file), stopped when enough
        name = p.name
        t = _crop(corpus, name, p.occupancy, p.known, p.resolution or 0.05, window)
        if (t.known & ~t.truth).sum() >= MIN_FREE_CELLS:
            out.append(t)
            if len(out) == n:
                break
    return out


#: the guide a run on plan files scores when ``--guides`` is not given: the one learned on both floor-plan corpora,
#: symmetrised (the headline's guide; the best on the real logs' buildings, docs/results.md)
PLAN_FILES_GUIDE = "houseexpo+ipa@sym"
#: the prior kinds a run on plan files alone scores when ``--priors`` is not given (each learned on every
#: ``--train`` corpus): the uniform prior, the tempered backed-off tables, the tempered 8-neighbour MRF and the
#: pattern field, as the results page scores the real logs' buildings
PLAN_FILES_PRIORS: tuple[str, ...] = ("independent", "patch3_bo@cal", "border_bo@cal", "mrf8@cal", "field2")


def check_plan_files(files: Sequence[Path]) -> None:
    """Refuse (:class:`LeakageError`) plan files that are plans of the corpora
    (:func:`~ogm_ppl.datasets.plan_files.corpus_copy`: under the corpora's folder, the same bytes, a HouseExpo
    layout under a corpus plan's id, or a near copy of its pixels in any turn or flip), and unreadable ones
    (:class:`~ogm_ppl.datasets.plan_files.PlanFileError`); the error names every such file, one a line."""
    from ogm_ppl.datasets.plan_files import corpus_copy

    leaks: list[str] = []
    bad: list[PlanFileError] = []
    for f in files:
        try:
            copy = corpus_copy(f)
        except PlanFileError as e:
            bad.append(e)
            continue
        if copy is not None:
            leaks.append(f"{f}: {copy}; score it as its corpus instead")
    if leaks:
        raise LeakageError("\n".join(leaks + [str(e) for e in bad]))
    if bad:
        raise _every_error(bad)


def _every_error(errors: Sequence[PlanFileError]) -> PlanFileError:
    """One :class:`~ogm_ppl.datasets.plan_files.PlanFileError` whose message names every file of ``errors``, one a
    line (the first file is its ``path``)."""
    rest = "".join(f"\n{e}" for e in errors[1:])
    return PlanFileError(errors[0].path, errors[0].problem + rest)


def plan_file_maps(
    paths: Sequence[Path],
    n: int | None,
    window: int,
    pixel_size: float | None,
    label: str = "files",
    outside: str = "occupied",
) -> list[TestMap]:
    """The first ``n`` (``None``: all) plans of ``paths`` (:func:`~ogm_ppl.datasets.plan_files.plan_files`: ROS
    map YAMLs, HouseExpo layouts, images or folders of them, read at 0.05 m a cell by
    :func:`~ogm_ppl.datasets.plan_files.load_plan_file`) whose chosen window holds at least 200 known free
    cells, each cropped to it; corpus plans refused (:func:`check_plan_files`)."""
    from ogm_ppl.datasets.plan_files import load_plan_file, plan_files, plan_names

    files = plan_files(paths)
    check_plan_files(files)
    out: list[TestMap] = []
    bad: list[PlanFileError] = []
    for f, name in zip(files, plan_names(files)):
        if n is not None and len(out) == n and not bad:
            break
        try:
            p = load_plan_file(f, pixel_size=pixel_size, name=name, corpus=label, outside=outside)
        except PlanFileError as e:  # read on, to name every bad file at once
            bad.append(e)
            continue
        t = _crop(label, name, p.occupancy, p.known, p.resolution or 0.05, window)
        if (t.known & ~t.truth).sum() >= MIN_FREE_CELLS and (n is None or len(out) < n):
            out.append(t)
    if bad:
        raise _every_error(bad)
    if not out:
        raise NoUsablePlanError(
            f"no plan of {', '.join(str(p) for p in paths)} has a {window}-cell window with {MIN_FREE_CELLS} known "
            "free cells"
        )
    return out


def plan_digests(paths: Sequence[Path]) -> dict[str, str]:
    """SHA-256 of every plan file of ``paths`` (and of the image each YAML names), by path: what a resumed run
    must find unchanged."""
    from ogm_ppl.datasets.plan_files import plan_file_pieces, plan_files

    return {str(q): hashlib.sha256(q.read_bytes()).hexdigest() for f in plan_files(paths) for q in plan_file_pieces(f)}


def generated_windows(n: int, shape: int, window: int, seed0: int) -> list[TestMap]:
    """``n`` generated maps, map ``i`` = ``generate_map(KINDS[i % 4], (shape, shape), seed=seed0 + i)``,
    cropped to ``window``."""
    out: list[TestMap] = []
    for i in range(n):
        kind = MAP_KINDS[i % len(MAP_KINDS)]
        m = generate_map(kind, (shape, shape), seed=seed0 + i, border=20)
        out.append(_crop("generated", f"{kind}/seed{seed0 + i}", m, np.ones_like(m), 0.05, window))
    return out
