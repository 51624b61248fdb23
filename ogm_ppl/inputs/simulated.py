"""The shipped kind that reads no file: ``simulated``, a stop-and-scan dataset (thesis Section 6.1) on a generated
ground-truth map or a floor plan of one's own. Its options are the whole input; its pieces (the scene, the route,
the scans) are public so that an experiment builds a scene and its route once and scans it at several
sparsities (:mod:`ogm_ppl.experiment.tasks`)."""

from __future__ import annotations

import hashlib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ogm_ppl.grid import Grid
from ogm_ppl.inputs.kinds import InputData, InputKind, register_input_kind
from ogm_ppl.options import Choice, Float, Int, Kind, Optional, ParamError, Text, _Bad, param

__all__ = [
    "MAP_KINDS",
    "Scene",
    "SimulatedOptions",
    "plan_digest",
    "simulated_route",
    "simulated_scans",
    "simulated_scene",
]

#: the generated maps (:func:`~ogm_ppl.datasets.generate_map`), and ``"mixed"``: those kinds in turn by map seed
MAP_KINDS = ("office", "corridor", "cluttered", "hall", "mixed")
_GENERATED = ("map", "size", "border", "map_seed")


class Size(Kind):
    """A generated map's cells: ``N`` (``N x N``) or ``[rows, cols]``, at least 60 each; as ``[rows, cols]``."""

    def value(self, v):
        if isinstance(v, int) and not isinstance(v, bool):
            v = [v, v]
        ok = isinstance(v, (list, tuple)) and len(v) == 2
        if not (ok and all(isinstance(s, int) and not isinstance(s, bool) for s in v)):
            raise _Bad(f"must be an int or [rows, cols], got {v!r}")
        if min(v) < 60:
            raise _Bad(f"generated maps need at least 60 x 60 cells, got {list(v)}")
        return [int(s) for s in v]

    def text(self, s):
        try:
            return self.value([int(x) for x in s.lower().split("x")] if "x" in s.lower() else int(s))
        except ValueError:
            raise _Bad(f"expected N or RowsxCols, got {s!r}") from None

    def describe(self):
        return "N or [rows, cols] (>= 60)"


@dataclass(frozen=True)
class SimulatedOptions:
    """The options of a simulated scene: the map (generated, or a plan), the route and the scans."""

    map: str | None = param(
        None,
        Optional(Choice(*MAP_KINDS)),
        "a generated map's kind ('mixed': the kinds in turn by map_seed); none: office",
    )
    size: object = param(None, Optional(Size()), "a generated map's cells: N or [rows, cols] (none: 500)")
    border: int | None = param(
        None, Optional(Int(lo=1)), "a generated map's outer wall in cells, at most min(size) // 4 (none: 20)"
    )
    map_seed: int | None = param(None, Optional(Int(lo=0)), "seeds the generated map (none: 0)")
    plan: str | None = param(
        None,
        Optional(Text()),
        "instead of a generated map, a floor plan file (ogm_ppl.datasets.plan_files: an image, a ROS map YAML or a "
        "HouseExpo layout); its unknown cells are walls, the image's top row at the grid's top",
    )
    pixel_size: float | None = param(None, Optional(Float(0, lo_open=True)), "metres per pixel of a plan image")
    resolution: float = param(0.05, Float(0, lo_open=True), "metres per cell")
    seed: int = param(0, Int(lo=0), "seeds the route and the range noise")
    poses: int | None = param(
        None, Optional(Int(lo=1)), "at most this many stops (none: explore until 95 % of the free space is seen)"
    )
    beams: int = param(720, Int(lo=1), "beams per 360-degree scan")
    max_range_cells: float = param(75.0, Float(0, lo_open=True), "the sensor's maximum range in cells")
    sigma_cells: float = param(3.0, Float(0, lo_open=True), "Gaussian range noise in cells")
    pose_fraction: float = param(1.0, Float(0, 1, lo_open=True), "scan at an evenly spaced fraction of the stops")
    beam_step: int = param(1, Int(lo=1), "keep every beam_step-th beam")

    def check(self) -> None:
        if self.plan is not None:
            for k in _GENERATED:
                if getattr(self, k) is not None:
                    raise ParamError(k, "applies to generated maps, not to a plan")
        else:
            hi = min(self.effective()["size"]) // 4
            if self.border is not None and self.border > hi:
                raise ParamError("border", f"must be <= {hi}, got {self.border!r}")
        if self.beam_step > self.beams:
            raise ParamError("beam_step", f"{self.beam_step} exceeds beams = {self.beams}")

    def effective(self) -> dict[str, Any]:
        """Every option as used: a plan's (``plan``, ``pixel_size``) or a generated map's (``map``, ``size``,
        ``border``, ``map_seed``, defaults filled), then the grid's, the route's and the scans'."""
        if self.plan is not None:
            scene: dict[str, Any] = {"plan": self.plan, "pixel_size": self.pixel_size}
        else:
            size = self.size or [500, 500]  # Size() made it [rows, cols]
            scene = {"map": self.map or "office", "size": size, "border": 20 if self.border is None else self.border}
            scene["map_seed"] = self.map_seed or 0
        rest = ("resolution", "seed", "poses", "beams", "max_range_cells", "sigma_cells", "pose_fraction", "beam_step")
        return scene | {k: getattr(self, k) for k in rest}


@dataclass(frozen=True)
class Scene:
    """A simulated world: ``grid``, ``truth`` (``grid.shape`` bool: walls, and a plan's unknown cells),
    ``known`` (``grid.shape`` bool: the cells a plan knows; every cell of a generated map) and ``map_kind``
    (the generated kind, or ``"plan"``)."""

    grid: Grid
    truth: np.ndarray
    known: np.ndarray
    map_kind: str


def simulated_scene(
    *,
    map: str = "office",
    size=(500, 500),
    border: int = 20,
    map_seed: int = 0,
    plan: str | None = None,
    pixel_size: float | None = None,
    resolution: float = 0.05,
) -> Scene:
    """The :class:`Scene` of a generated map (``map``, ``size`` cells, ``border``, ``map_seed``; ``"mixed"``:
    the kinds in turn by ``map_seed``) or of the floor plan file ``plan`` (``pixel_size`` metres a pixel), at
    ``resolution`` metres a cell."""
    from ogm_ppl.datasets.mapgen import KINDS, generate_map

    if plan is not None:
        from ogm_ppl.datasets.plan_files import load_plan_file

        p = load_plan_file(plan, pixel_size=pixel_size, resolution=resolution, outside="unknown")
        known = np.flipud(np.asarray(p.known, bool))  # a plan's row 0 is the image's top, a grid's its bottom
        truth = np.flipud(np.asarray(p.occupancy, bool)) | ~known
        kind = "plan"
    else:
        kind = KINDS[map_seed % len(KINDS)] if map == "mixed" else map
        truth = generate_map(kind, tuple(size), seed=map_seed, border=border)
        known = np.ones_like(truth)
    return Scene(Grid(truth.shape, resolution=resolution), truth, known, kind)


def simulated_route(scene: Scene, *, poses: int | None, max_range_cells: float, seed: int) -> np.ndarray:
    """``P x 3`` stops (metres, radians) of a seeded exploration route over the scene's free space
    (:func:`~ogm_ppl.datasets.plan_route`)."""
    from ogm_ppl.datasets.stop_and_scan import plan_route

    return plan_route(scene.truth, scene.grid, num_poses=poses, max_range_cells=max_range_cells, seed=seed)


def simulated_scans(
    truth: np.ndarray,
    grid: Grid,
    route: np.ndarray,
    *,
    beams: int,
    max_range_cells: float,
    sigma_cells: float,
    seed: int,
    pose_fraction: float = 1.0,
    beam_step: int = 1,
):
    """The stop-and-scan readings (:func:`~ogm_ppl.datasets.stop_and_scan`) of ``truth`` on ``grid`` at the stops
    ``route``: ``beams`` per scan, range noise ``sigma_cells``, thinned by ``pose_fraction`` / ``beam_step``."""
    from ogm_ppl.datasets.stop_and_scan import stop_and_scan

    return stop_and_scan(
        truth,
        grid,
        route=route,
        beams=beams,
        max_range_cells=max_range_cells,
        sigma_cells=sigma_cells,
        seed=seed,
        pose_fraction=pose_fraction,
        beam_step=beam_step,
    )


def plan_digest(plan: str | Path) -> str:
    """SHA-256 of the files a plan is read from (an image, a ROS map's YAML and its image)."""
    from ogm_ppl.datasets.plan_files import plan_file_pieces

    h = hashlib.sha256()
    for piece in plan_file_pieces(plan):
        h.update(piece.read_bytes())
    return h.hexdigest()


def _identify(path, o: SimulatedOptions) -> str | None:
    return None if o.plan is None else plan_digest(o.plan)


def _read_simulated(path, o: SimulatedOptions) -> InputData:
    e = o.effective()
    scene = simulated_scene(**{k: e[k] for k in (*_GENERATED, "plan", "pixel_size", "resolution") if k in e})
    route = simulated_route(scene, poses=o.poses, max_range_cells=o.max_range_cells, seed=o.seed)
    data = simulated_scans(
        scene.truth,
        scene.grid,
        route,
        beams=o.beams,
        max_range_cells=o.max_range_cells,
        sigma_cells=o.sigma_cells,
        seed=o.seed,
        pose_fraction=o.pose_fraction,
        beam_step=o.beam_step,
    )
    settings = {**data.settings, **e, "map_kind": scene.map_kind, "known_share": float(scene.known.mean())}
    return InputData("simulated", None, data.scans, scene.grid, scene.truth, settings, data)


register_input_kind(
    InputKind(
        "simulated",
        SimulatedOptions,
        _read_simulated,
        "a stop-and-scan dataset simulated on a generated map or a floor plan (Section 6.1)",
        noun="simulated scene",
        identify=_identify,
        reads_file=False,
    )
)
