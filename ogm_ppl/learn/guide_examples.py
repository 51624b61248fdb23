r"""Training windows for a corpus guide: maps of a corpus or of plan files, scanned by the simulator.

A training example is a ``window x window`` crop of a map ``m`` with the guide's input for simulated readings
``z ~ p(z | m)`` (:func:`~ogm_ppl.inference.variational.amortised_features.evidence_features`, ``C x H x W``), the truth
``m`` and two masks: the scored cells ``S(m)`` (known and not pinned free by the scans) and the unseen
near-mapped cells (known, within 10 cells of a reached cell, not reached; the cells the validation loss and the
temperature are measured on, thesis Section 5.2.3). Three ways to scan:

* :func:`make_example`: one window (half the time the one with the most wall-side cells,
  :func:`~ogm_ppl.calibration.heldout.choose_window`, as the calibration protocol crops its test maps; half
  anywhere with 200 known free cells), scanned on its own by the stop-and-scan simulator (Section 6.1);
* :func:`scene_examples`: the whole map scanned along a planned route (the Table 6.4 simulator), then windows
  cropped from its features;
* :func:`driven_scans`: that route driven, a pose every ``S`` cells of path scanning ``fov`` degrees ahead.

A :class:`MapSource` names the maps of one source and reads them: a corpus's tables' training set or a
random sample of its training split (:func:`corpus_source`, :func:`~ogm_ppl.calibration.leakage.guide_plans`),
or plan files of one's own (:func:`files_source`). :func:`split_names` holds every fifth name out as a validation map.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from ogm_ppl.calibration.heldout import choose_window
from ogm_ppl.calibration.leakage import guide_plans, training_set
from ogm_ppl.datasets import floorplans as fp
from ogm_ppl.datasets.stop_and_scan import stop_and_scan
from ogm_ppl.grid import Grid
from ogm_ppl.inference.variational.amortised import evidence_features
from ogm_ppl.learn.guide_settings import CELL_M, FILES_SOURCE, MIN_FREE_CELLS, GuideTrainingSettings
from ogm_ppl.metrics import near_mapped_mask
from ogm_ppl.models import OccupancyModel
from ogm_ppl.priors import IndependentPrior
from ogm_ppl.priors.tables import FITTED_DIR
from ogm_ppl.progress import Progress
from ogm_ppl.raycast import raycast
from ogm_ppl.scans import Scans
from ogm_ppl.sensors import GaussianRange

__all__ = [
    "MIN_FREE_CELLS",
    "Example",
    "MapSource",
    "TooFewWindowsError",
    "TrainingMap",
    "batch",
    "build_set",
    "corpus_source",
    "driven_scans",
    "files_source",
    "generated_maps",
    "load_map",
    "make_example",
    "scanned",
    "scene_examples",
    "split_names",
    "split_plans",
]


class TooFewWindowsError(ValueError):
    """The maps of a source gave fewer usable windows than asked for."""


@dataclass
class Example:
    """One training window: features ``x`` (``C x H x W`` float32), truth ``y`` (``H x W`` float32, 1 =
    occupied), the scored cells ``S`` and the unseen near-mapped cells (``H x W`` bool each)."""

    x: torch.Tensor
    y: torch.Tensor
    scored: torch.Tensor
    unseen: torch.Tensor


@dataclass
class TrainingMap:
    """A map to draw windows from: ``occupancy`` / ``known`` ``H x W`` bool, metres per cell (``None``: none
    recorded, read as :data:`~ogm_ppl.learn.guide_settings.CELL_M`)."""

    occupancy: np.ndarray
    known: np.ndarray
    resolution: float | None


@dataclass(frozen=True)
class MapSource:
    """The maps of one source: ``label`` (a corpus, or ``"files"``), the map ``names`` (sorted), ``load(name)``
    reading one as a :class:`TrainingMap`, and ``record``: what the guide's record says of the source beyond
    its plans' names (e.g. the plan files' SHA-256)."""

    label: str
    names: tuple[str, ...]
    load: Callable[[str], TrainingMap]
    record: dict


def split_names(names: Iterable[str]) -> tuple[list[str], list[str]]:
    """``(training, validation)`` names: ``names`` sorted, every fifth one held out for validation."""
    ordered = sorted(names)
    val = ordered[::5]
    held = set(val)
    return [n for n in ordered if n not in held], val


def split_plans(corpus: str) -> tuple[list[str], list[str]]:
    """``(training, validation)`` plans of ``corpus``: its tables' training set
    (:func:`~ogm_ppl.calibration.leakage.training_set`) split by :func:`split_names`."""
    return split_names(training_set(corpus))


def generated_maps() -> dict[str, tuple]:
    """``training-set name -> (index, child seed, tables' provenance)`` of the maps the ``generated`` tables
    counted (:func:`~ogm_ppl.datasets.mapgen.iter_corpus` with the tables' recorded seed, ``n``, shape, kinds,
    border)."""
    prov = json.loads((FITTED_DIR / "prior_generated.json").read_text())["provenance"]
    children = np.random.SeedSequence(int(prov["seed"])).spawn(int(prov["n"]))
    return {f"seedstream:{c.entropy}/{tuple(c.spawn_key)}": (i, c, prov) for i, c in enumerate(children)}


def load_map(corpus: str, name: str) -> TrainingMap:
    """The training map ``name`` of ``corpus`` (a plan, or a generated map by its seed-stream name)."""
    if corpus == "generated":
        from ogm_ppl.datasets.mapgen import generate_map

        i, child, prov = generated_maps()[name]
        kinds = prov["kinds"]
        occ = generate_map(
            kinds[i % len(kinds)], tuple(prov["shape"]), np.random.default_rng(child), border=int(prov["border"])
        )
        return TrainingMap(occ, np.ones_like(occ), CELL_M)
    p = fp.load_plan(corpus, name)
    return TrainingMap(p.occupancy, p.known, p.resolution)


def corpus_source(corpus: str, sample: int | None = None, seed: int = 0) -> MapSource:
    """The maps of ``corpus`` a guide learns from (:func:`~ogm_ppl.calibration.leakage.guide_plans`): the
    training set of its shipped tables (rebuilt from their provenance), or with ``sample`` a random ``sample``
    of its training split drawn with ``seed``. The record says which (``split``, ``sample``). ``houseexpo-full``
    plans are read from one pass over its file, made on the first plan asked for (:func:`_outline_loader`)."""
    names, record = guide_plans(corpus, sample, seed)
    if sample is None:
        record["tables_provenance"] = f"{FITTED_DIR.name}/prior_{corpus}.json"
    if corpus == "houseexpo-full":
        load = _outline_loader(names)
    else:

        def load(name: str) -> TrainingMap:
            return load_map(corpus, name)

    return MapSource(corpus, tuple(names), load, record)


def _outline_loader(names: Sequence[str]) -> Callable[[str], TrainingMap]:
    """A loader of ``houseexpo-full`` plans that reads the outlines of all ``names`` in one pass over the
    corpus file when the first plan is asked for (a few kB each), then rasterises each plan asked for from its
    outline (:func:`~ogm_ppl.datasets.floorplans.plan_from_outline`), instead of a pass over the file a plan."""
    from ogm_ppl.datasets.floorplans import houseexpo_full

    outlines: dict[str, np.ndarray] = {}

    def load(name: str) -> TrainingMap:
        if not outlines:
            outlines.update(houseexpo_full.records(names))
        p = fp.plan_from_outline(name, outlines[name])
        return TrainingMap(p.occupancy, p.known, p.resolution)

    return load


def files_source(paths: Sequence[Path], pixel_size: float | None = None) -> MapSource:
    """The plan files of ``paths`` (files or folders, :func:`~ogm_ppl.datasets.plan_files.plan_files`) read at
    :data:`~ogm_ppl.learn.guide_settings.CELL_M` a cell, named by
    :func:`~ogm_ppl.datasets.plan_files.plan_names`; the record holds each file's SHA-256
    (:func:`~ogm_ppl.calibration.heldout.plan_digests`). Raises
    :class:`~ogm_ppl.datasets.plan_files.PlanFileError` for a missing or unreadable file, or fewer than 2 plans
    (one to train on, one to validate on)."""
    from ogm_ppl.calibration.heldout import plan_digests
    from ogm_ppl.datasets.plan_files import PlanFileError, load_plan_file, plan_files, plan_names

    files = plan_files(paths)
    names = plan_names(files)
    if len(files) < 2:
        raise PlanFileError(files[0], "one plan: a guide needs 2 or more (every fifth one validates)")
    by_name = dict(zip(names, files, strict=True))
    for f in files:  # read each once now, so a bad file is named before any training
        load_plan_file(f, pixel_size=pixel_size, resolution=CELL_M)

    def load(name: str) -> TrainingMap:
        p = load_plan_file(by_name[name], pixel_size=pixel_size, resolution=CELL_M, name=name)
        return TrainingMap(p.occupancy, p.known, p.resolution)

    digests = {name: d for name, d in zip(names, _file_digests(files, plan_digests), strict=True)}
    return MapSource(FILES_SOURCE, tuple(sorted(names)), load, {"plan_files_sha256": digests})


def _file_digests(files: Sequence[Path], plan_digests) -> list[str]:
    """One SHA-256 a plan: of its file's, and (a ROS map) its image's, digests joined."""
    out = []
    for f in files:
        d = plan_digests([f])
        out.append(d[str(f)] if len(d) == 1 else "+".join(d[k] for k in sorted(d)))
    return out


def _random_window(occ: np.ndarray, known: np.ndarray, window: int, rng: np.random.Generator) -> tuple[int, int] | None:
    H, W = occ.shape
    h, w = min(window, H), min(window, W)
    for _ in range(20):
        r = int(rng.integers(0, H - h + 1))
        c = int(rng.integers(0, W - w + 1))
        if (known[r : r + h, c : c + w] & ~occ[r : r + h, c : c + w]).sum() >= MIN_FREE_CELLS:
            return r, c
    return None


def scanned(grid: Grid, scans: Scans, sigma: float, known: np.ndarray) -> tuple[torch.Tensor, np.ndarray, np.ndarray]:
    """The guide's input for ``scans`` of ``grid`` (:func:`evidence_features`, no tile phase, ``C x H x W``),
    the pinned cells and the unseen near-mapped cells (``H x W`` bool: known, within 10 cells of a reached
    cell, not reached)."""
    rays = raycast(grid, scans)
    model = OccupancyModel(grid, rays, GaussianRange(sigma), IndependentPrior(0.5, grid.num_cells))
    reached = rays.reached().reshape(grid.shape)
    pinned = model.known_free.numpy().reshape(grid.shape)
    return evidence_features(model, phase=(0, 0)), pinned, near_mapped_mask(reached, 10.0) & known & ~reached


def make_example(plan: TrainingMap, s: GuideTrainingSettings, rng: np.random.Generator) -> Example | None:
    """One ``s.window`` window of ``plan`` scanned on its own (``s.poses`` stops, the simulator's sensor) with
    a fresh seed; ``None`` when the window holds fewer than 200 known free cells or no stop with the
    simulator's clearance."""
    occ, known, window = plan.occupancy, plan.known, s.window
    if rng.random() < 0.5:
        rc: tuple[int, int] | None = choose_window(occ, known, window)
    else:
        rc = _random_window(occ, known, window, rng)
    if rc is None:
        return None
    r0, c0 = rc
    h, w = min(window, occ.shape[0]), min(window, occ.shape[1])
    truth, kn = occ[r0 : r0 + h, c0 : c0 + w], known[r0 : r0 + h, c0 : c0 + w]
    if (kn & ~truth).sum() < MIN_FREE_CELLS:
        return None
    grid = Grid(truth.shape, resolution=plan.resolution or CELL_M)
    try:
        data = stop_and_scan(
            truth,
            grid,
            num_poses=s.poses,
            beams=s.beams,
            max_range_cells=s.range_cells,
            sigma_cells=s.sigma,
            seed=int(rng.integers(2**31)),
        )
    except ValueError:  # no stop keeps the robot's clearance in this window: draw another
        return None
    x, pinned, unseen = scanned(grid, data.scans, s.sigma, kn)
    return Example(
        x=x,
        y=torch.from_numpy(truth.astype(np.float32)),
        scored=torch.from_numpy(kn & ~pinned),
        unseen=torch.from_numpy(unseen),
    )


def scene_examples(plan: TrainingMap, crops: int, s: GuideTrainingSettings, rng: np.random.Generator) -> list[Example]:
    """The whole map scanned along a planned route (the Table 6.4 simulator: ``s.poses = 0`` lets the route
    planner choose the stops; planned for ``s.plan_range_cells``, default the range), or driven
    (:func:`driven_scans`, ``s.drive``), then ``crops`` random ``s.window`` windows of its features with 200
    known free cells (at most ``4 * crops`` tries)."""
    from ogm_ppl.datasets.stop_and_scan import plan_route

    occ, known, window = plan.occupancy, plan.known, s.window
    grid = Grid(occ.shape, resolution=plan.resolution or CELL_M)
    seed = int(rng.integers(2**31))
    plan_range = s.plan_range_cells or s.range_cells
    route = plan_route(occ, grid, num_poses=s.poses or None, max_range_cells=plan_range, seed=seed)
    if s.drive:
        scans = driven_scans(occ, grid, route, s, rng)
    else:
        scans = stop_and_scan(
            occ, grid, route=route, beams=s.beams, max_range_cells=s.range_cells, sigma_cells=s.sigma, seed=seed
        ).scans
    x, pinned, unseen = scanned(grid, scans, s.sigma, known)
    H, W = occ.shape
    h, w = min(window, H), min(window, W)
    out: list[Example] = []
    for _ in range(4 * crops):
        if len(out) == crops:
            break
        r, c = int(rng.integers(0, H - h + 1)), int(rng.integers(0, W - w + 1))
        sl = (slice(r, r + h), slice(c, c + w))
        if (known[sl] & ~occ[sl]).sum() < MIN_FREE_CELLS:
            continue
        out.append(
            Example(
                x=x[:, sl[0], sl[1]].clone(),
                y=torch.from_numpy(occ[sl].astype(np.float32)),
                scored=torch.from_numpy(known[sl] & ~pinned[sl]),
                unseen=torch.from_numpy(unseen[sl]),
            )
        )
    return out


def driven_scans(
    occ: np.ndarray, grid: Grid, route: np.ndarray, s: GuideTrainingSettings, rng: np.random.Generator
) -> Scans:
    """Scans taken while driving ``route`` (:func:`~ogm_ppl.datasets.drive_route`): a pose every ``S`` cells
    of path, ``S`` drawn from ``s.drive`` for each map, each scanning ``s.fov`` degrees ahead with beams
    ``360 / s.beams`` degrees apart and the simulator's range noise ``s.sigma``."""
    from ogm_ppl.datasets import drive_route, simulate_scans

    assert s.drive is not None
    step = float(s.drive[int(rng.integers(len(s.drive)))])
    poses = drive_route(occ, grid, route, step_cells=step)
    n = max(1, round(s.beams * s.fov / 360))
    angles = np.arange(n) * (2 * np.pi / s.beams) - (n - 1) * np.pi / s.beams
    return simulate_scans(grid, occ, poses, angles, s.range_cells * grid.resolution, s.sigma, rng)


def build_set(
    source: MapSource,
    names: Sequence[str],
    n: int,
    s: GuideTrainingSettings,
    seed: int,
    label: str,
    progress: bool = False,
) -> list[Example]:
    """``n`` windows of maps drawn (``default_rng(seed)``) from ``names`` of ``source``: each scanned on its
    own (:func:`make_example`), or with ``s.scan_whole_map`` ``s.crops`` windows a scene of the whole map
    (:func:`scene_examples`). At most ``4 n`` maps are drawn; fewer usable windows raise
    :class:`TooFewWindowsError`."""
    rng = np.random.default_rng(seed)
    plans: dict[str, TrainingMap] = {}
    out: list[Example] = []
    tries = 0
    with Progress(n, f"{source.label} {label} windows", unit="window", enabled=progress, after=10.0) as bar:
        while len(out) < n and tries < 4 * n:
            tries += 1
            name = names[int(rng.integers(len(names)))]
            if name not in plans:
                plans[name] = source.load(name)
            if s.scan_whole_map:
                new = scene_examples(plans[name], min(s.crops, n - len(out)), s, rng)
                plans.pop(name)  # whole maps are large and each is scanned afresh
            else:
                ex = make_example(plans[name], s, rng)
                new = [] if ex is None else [ex]
            out += new
            if new:
                bar.update(len(new))
    if len(out) < n:
        raise TooFewWindowsError(f"{source.label}: only {len(out)} usable {label} windows of {n} after {tries} tries")
    return out


def batch(exs: Sequence[Example], sym: int) -> tuple[torch.Tensor, ...]:
    """Stack windows of one shape, turned by symmetry ``sym`` (0-7: ``sym % 4`` quarter turns, then a flip
    when ``sym >= 4``): ``(x, y, scored, unseen)``, ``B x C x H x W`` and ``B x H x W``."""

    def t(a: torch.Tensor) -> torch.Tensor:
        a = torch.rot90(a, sym % 4, dims=(-2, -1))
        return torch.flip(a, dims=(-1,)) if sym >= 4 else a

    return tuple(torch.stack([t(getattr(e, k)) for e in exs]) for k in ("x", "y", "scored", "unseen"))
