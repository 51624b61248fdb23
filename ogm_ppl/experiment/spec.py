r"""Experiment specs (TOML): which datasets, which algorithms, which metrics, what to write.

A spec is read with :func:`load_spec` (or built from a dict with :func:`parse_spec`) and validated as a
whole: every error names the file, the table entry and the key (``smoke.toml: datasets[0] ('office')
.sigma_cells: must be a number > 0, got -1``), and unknown keys are refused (a typo must not silently
fall back to a default).

Tables (every key optional unless marked *required*; defaults in brackets)::

    [experiment]        name [file stem], seed [0], description [""], kind ["map"; "active": an active-mapping
                        spec, its own tables: ogm_ppl.experiment.active], max_cells [50,000,000: a dataset
                        whose grid has more cells is refused: when the spec is read, or for a log without an
                        extent when its base task has read the log, before any map is built]
    [[datasets]]        kind = "simulated" | "log" | "bag" (*required*), name (*required*, [A-Za-z0-9_.-]+)
      simulated:        map ["office"; a mapgen kind or "mixed" = kinds in turn by map_seed],
                        size [500] (int or [rows, cols]), border [20], resolution [0.05] (m/cell),
                        map_seed [0], seed [derived], poses [route until coverage], beams [720],
                        max_range_cells [75], sigma_cells [3.0], pose_fraction [1.0], beam_step [1];
                        or, instead of map, size, border and map_seed, plan = a floor plan of your own
                        (ogm_ppl.datasets.plan_files: an image, a ROS map YAML or a HouseExpo layout; relative
                        to the spec file) and pixel_size (metres, for an image); its unknown cells are walls;
                        the grid's origin is (0, 0) at the bottom-left corner of the cropped plan, the image's
                        top row at the top (largest y)
      log:              path (*required*; relative to the spec file; ~ and $VARS expanded),
                        reader [{max_usable_range = 20.0}] (read_carmen options), resolution [0.05],
                        extent [x0, y0, width, height] metres (else the log's extent + margin [1.0]),
                        sigma_cells [3.0] (the models' range noise), pose_fraction [1.0], beam_step [1]
                        or beam_increment_deg (the same as a multiple of the log's increment),
                        benchmark [{delta = "haehnel", threshold = 0.20, prior = 0.5}]
      bag:              a ROS bag (ogm_ppl.datasets.read_bag): path (*required*; a .bag file or a ROS 2 bag
                        folder / .db3 / .mcap), scan_topic (*required*), pose_topic or tf = true (one is
                        *required*), map_frame ["map"], laser_offset [[0, 0, 0]] (x, y, yaw of the laser in
                        the robot frame; pose_topic only), pose_tolerance [0.1] (s), reader [{max_usable_range
                        = 20.0}] (read_bag options: strict, max_usable_range, usable_range_rule, no_return,
                        no_return_threshold, min_range, max_range, widen; checked here), and the keys of log
    [[algorithms]]      kind = a map method (*required*; ``ogm-ppl methods`` lists them with their
                        parameters), name (*required*), and the method's parameters (ogm_ppl.methods):
      ogm:              delta ["haehnel"], prior [0.5], clamp [none: [lo, hi] log-odds],
                        fit ["none"; "setting": refit the named term (pN, moravec_opt, ...) for the dataset's
                        sigma_cells and max range in cells, Section 2.5; a shipped fitted term used
                        outside its setting warns, and the warning is kept in the run's result],
                        sigma_cells [the dataset's]
      gibbs:            prior ["independent"; see ogm_ppl.priors.named], patch [1; L = 9 is [3, 3]],
                        sweeps [100], burn_in [0], chains [1], init ["ogm"; "prior", "free", "occupied",
                        "guide:CORPUS": the mode of a corpus guide], init_delta ["haehnel"],
                        scan ["systematic"], update ["gibbs"], p_rand_patch [0.0], sigma_cells [the
                        dataset's], checkpoint_every [10], record [5] (F1 records of the running marginals),
                        threads [none: the serial kernel; N: chromatic tile sweeps on N threads]
      patch_map:        patch [[3, 3]], mode ["offline" | "online"], overlap [false],
                        prior ["independent"], sigma_cells [the dataset's]
      amortised:        guide ["shipped"; "corpus:CORPUS": the guide learned on a corpus's plans; or a .npz]
      also:             metropolis, vi, guided_gibbs, tempering, and the aliases p21, elfes, patch
      every model-based method (gibbs, patch_map, metropolis, vi, guided_gibbs, tempering) also takes
                        sensor ["gaussian"; see ogm_ppl.sensors.sensor_by_name] and p_rand [0.0; vi 0.001]
                        (the sensor model's share of random readings)
    [metrics]           mask ["auto": "known" for simulated, "near_mapped" for logs; "all": every cell;
                        "known": a plan's walls and free space, not its exterior nor the crop's margin (every
                        cell of a generated map)], near_mapped_distance
                        [10.0] (cells), touched_only [true], thresholds [99: 0.01..0.99, or a list],
                        scores [["f1", "auc", "max_precision"]; also "nll_bits", "brier", "ece"]
    [output]            maps [true] (per-task npz + PNG), figures [true], fpfn ["first" | "all" |
                        "none"], fpfn_thresholds [[0.1, 0.2, 0.6]], dpi [100]

**Sweeps.** In a dataset entry, ``map_seed``, ``seed``, ``pose_fraction`` and ``beam_step`` may be lists:
the entry expands into the Cartesian product, one dataset each, named ``NAME-m<map_seed>-s<seed>
-pf<pose_fraction>-bs<beam_step>`` (only the swept keys appear). Datasets of one entry that differ only
by ``map_seed`` / ``seed`` are *repeats* of one *condition*; their counts are pooled in the tables (as
the thesis pooled its 100 datasets). Conditions that differ by ``pose_fraction`` / ``beam_step`` give the
F1-against-sparsity figure.

**Seeds.** :func:`derive_seed` turns the experiment seed and a task's names into a seed through
``numpy.random.SeedSequence(seed, spawn_key=crc32 of each name)``: a task's seed depends on what it is,
not on its position in the spec, so adding an algorithm or a dataset changes no other task's result.
"""

from __future__ import annotations

import hashlib
import itertools
import json
import math
import os
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np

from ogm_ppl.experiment.spec_tables import SpecError, Table, check_name, derive_seed, named_entry
from ogm_ppl.grid import MAX_CELLS

__all__ = [
    "AlgorithmSpec",
    "DatasetSpec",
    "ExperimentSpec",
    "MetricsSpec",
    "OutputSpec",
    "parse_map_spec",
]

MAP_KINDS = ("office", "corridor", "cluttered", "hall", "mixed")
SWEEP_KEYS = {"map_seed": "m", "seed": "s", "pose_fraction": "pf", "beam_step": "bs"}
REPEAT_KEYS = ("map_seed", "seed")
READER_KEYS = (
    "strict",
    "max_usable_range",
    "usable_range_rule",
    "no_return",
    "no_return_threshold",
    "min_range",
    "max_range",
    "messages",
    "apply_laser_offset",
)
#: read_bag options a bag entry's reader table may set: (kind, lower bound, lower bound open, choices)
BAG_READER_KEYS: dict[str, tuple] = {
    "strict": ("bool", None, False, None),
    "max_usable_range": ("float", 0, True, None),
    "usable_range_rule": ("str", None, False, ("drop", "max")),
    "no_return": ("str", None, False, ("drop", "max")),
    "no_return_threshold": ("float", 0, True, None),
    "min_range": ("float", 0, False, None),
    "max_range": ("float", 0, True, None),
    "widen": ("str", None, False, ("decimal", "binary")),
}
SCORES = ("f1", "auc", "max_precision", "nll_bits", "brier", "ece")


# ------------------------------------------------------------------------------------------ spec types
@dataclass(frozen=True)
class DatasetSpec:
    """One dataset after expansion of the sweeps (``params`` holds scalars only)."""

    name: str
    entry: str
    kind: str
    params: dict
    condition: str  # the entry plus its sparsity values: repeats of a condition are pooled
    base: str  # datasets sharing a base share its expensive part (a planned route, a read log)
    base_params: dict
    measurement_fraction: float  # pose_fraction / beam_step (Fig. 6.17's x axis)


@dataclass(frozen=True)
class AlgorithmSpec:
    """One algorithm: a registered map method (``kind``) and its validated parameters (a plain dict)."""

    name: str
    kind: str
    params: dict

    @property
    def chains(self) -> int:
        return int(self.params.get("chains", 1))

    @property
    def method(self):
        """The :class:`~ogm_ppl.methods.MapMethod` of ``kind``."""
        from ogm_ppl.methods import get_method

        return get_method(self.kind)

    def method_params(self):
        """The method's parameter dataclass of :attr:`params`."""
        return self.method.params(**self.params)

    @property
    def records_metrics(self) -> bool:
        """Whether a run records scores of its running marginals (its result depends on the metrics)."""
        return self.method.sampler


@dataclass(frozen=True)
class MetricsSpec:
    mask: str = "auto"
    near_mapped_distance: float = 10.0
    touched_only: bool = True
    thresholds: tuple = tuple(np.round(np.linspace(0.01, 0.99, 99), 10).tolist())
    scores: tuple = ("f1", "auc", "max_precision")

    def mask_for(self, dataset_kind: str) -> str:
        """The mask scored on a dataset of ``dataset_kind``: :attr:`mask`, ``"auto"`` read as
        ``"near_mapped"`` for logs and bags and ``"known"`` for simulated data."""
        if self.mask != "auto":
            return self.mask
        return "near_mapped" if dataset_kind in ("log", "bag") else "known"


@dataclass(frozen=True)
class OutputSpec:
    maps: bool = True
    figures: bool = True
    fpfn: str = "first"
    fpfn_thresholds: tuple = (0.1, 0.2, 0.6)
    dpi: int = 100


@dataclass(frozen=True)
class ExperimentSpec:
    """A validated experiment: expanded datasets, algorithms, metrics and output settings."""

    name: str
    seed: int
    description: str
    datasets: tuple
    algorithms: tuple
    metrics: MetricsSpec = field(default_factory=MetricsSpec)
    output: OutputSpec = field(default_factory=OutputSpec)
    source: str = "<dict>"
    raw: dict = field(default_factory=dict, repr=False)
    #: the largest grid (cells) a dataset may have
    max_cells: int = MAX_CELLS

    def only(self, algorithms) -> ExperimentSpec:
        """The same spec with only the named algorithms (in the spec's order): run a subset now, the rest
        later into the same output folder (a rerun resumes every task already done). Raises
        :class:`SpecError` naming an unknown algorithm."""
        names = list(dict.fromkeys(algorithms))
        known = [a.name for a in self.algorithms]
        unknown = [n for n in names if n not in known]
        if unknown:
            raise SpecError(f"{self.source}: no algorithm {unknown[0]!r} in the spec; it has {', '.join(known)}")
        return replace(self, algorithms=tuple(a for a in self.algorithms if a.name in names))

    def to_json(self) -> dict:
        """The normalised spec (JSON-able)."""
        return {
            "name": self.name,
            "seed": self.seed,
            "description": self.description,
            "source": self.source,
            "datasets": [asdict(d) for d in self.datasets],
            "algorithms": [asdict(a) for a in self.algorithms],
            "metrics": asdict(self.metrics),
            "output": asdict(self.output),
        }


# ------------------------------------------------------------------------------------------ reading
def _check_delta(t: Table, key: str, default: str) -> str:
    name = t.get(key, "str", default)
    from ogm_ppl.models import delta_by_name

    try:
        delta_by_name(name)
    except (ValueError, KeyError, FileNotFoundError) as e:
        t.fail(key, f"unknown update term ({e})")
    return name


def _generated_keys(t: Table) -> dict:
    """``map``, ``size``, ``border`` and ``map_seed`` of a simulated dataset on a generated map."""
    p: dict = {"map": t.get("map", "str", "office", choices=MAP_KINDS)}
    size = t.raw("size", 500)
    if isinstance(size, int) and not isinstance(size, bool):
        size = [size, size]
    if not (
        isinstance(size, list) and len(size) == 2 and all(isinstance(s, int) and not isinstance(s, bool) for s in size)
    ):
        t.fail("size", f"must be an int or [rows, cols], got {size!r}")
    if min(size) < 60:
        t.fail("size", f"generated maps need at least 60 x 60 cells, got {size}")
    p["size"] = [int(s) for s in size]
    p["border"] = t.get("border", "int", 20, lo=1, hi=min(size) // 4)
    p["map_seed"] = t.get("map_seed", "int", 0, sweep=True, lo=0)
    return p


def _plan_keys(t: Table, base_dir: Path) -> dict:
    """``plan`` (resolved like a log's path), the SHA-256 of its files (a changed plan is a new dataset) and
    ``pixel_size`` of a simulated dataset on a floor plan of your own."""
    from ogm_ppl.datasets.plan_files import plan_file_pieces

    raw = t.get("plan", "str")
    path = Path(os.path.expandvars(os.path.expanduser(raw)))
    if not path.is_absolute():
        path = (base_dir / path).resolve()
    if not path.is_file():
        t.fail("plan", f"no such plan file: {path}")
    h = hashlib.sha256()
    for piece in plan_file_pieces(path):
        h.update(piece.read_bytes())
    pixel = t.get("pixel_size", "float", None, lo=0, lo_open=True)
    return {"plan": str(path), "plan_sha256": h.hexdigest(), "pixel_size": pixel}


def _check_plan(t: Table, p: dict, max_cells: int) -> None:
    """Read the plan once as :func:`~ogm_ppl.experiment.tasks.run_base` will, so a bad file fails here."""
    from ogm_ppl.datasets.plan_files import PlanFileError, load_plan_file

    try:
        plan = load_plan_file(p["plan"], pixel_size=p["pixel_size"], resolution=p["resolution"])
    except (PlanFileError, OSError) as e:
        t.fail("plan", str(e))
    rows, cols = plan.shape
    _too_many(t, "plan", rows, cols, max_cells, f"{p['plan']} at {p['resolution']} m a cell")


def _too_many(t: Table, key: str, rows: int, cols: int, max_cells: int, what: str) -> None:
    if rows * cols > max_cells:
        t.fail(
            key,
            f"{what} gives a grid of {rows:,} x {cols:,} = {rows * cols:,} cells, over the limit of {max_cells:,} "
            "([experiment] max_cells)",
        )


def _dataset_entry(source: str, base_dir: Path, i: int, d, seed: int, max_cells: int = MAX_CELLS) -> list[DatasetSpec]:
    t, name = named_entry(source, "datasets", i, d)
    kind = t.get("kind", "str", required=True, choices=("simulated", "log", "bag"))
    p: dict = {}
    if kind == "simulated":
        if t.has("plan"):  # scanned on a floor plan of your own
            for k in ("map", "size", "border", "map_seed"):
                if t.has(k):
                    t.fail(k, "applies to generated maps, not to a plan")
            p.update(_plan_keys(t, base_dir))
        else:
            p.update(_generated_keys(t))
            rows, cols = p["size"]
            _too_many(t, "size", rows, cols, max_cells, f"size = {p['size']}")
        p["resolution"] = t.get("resolution", "float", 0.05, lo=0, lo_open=True)
        if "plan" in p:
            _check_plan(t, p, max_cells)
        p["seed"] = t.get("seed", "int", derive_seed(seed, "dataset", name, bits=32), sweep=True, lo=0)
        p["poses"] = t.get("poses", "int", None, lo=1)
        p["beams"] = t.get("beams", "int", 720, lo=1)
        p["max_range_cells"] = t.get("max_range_cells", "float", 75.0, lo=0, lo_open=True)
        p["sigma_cells"] = t.get("sigma_cells", "float", 3.0, lo=0, lo_open=True)
        p["pose_fraction"] = t.get("pose_fraction", "float", 1.0, sweep=True, lo=0, lo_open=True, hi=1)
        p["beam_step"] = t.get("beam_step", "int", 1, sweep=True, lo=1)
        for bs in np.atleast_1d(p["beam_step"]):
            if bs > p["beams"]:
                t.fail("beam_step", f"{bs} exceeds beams = {p['beams']}")
        shared = ("resolution", "seed", "poses", "max_range_cells")
        if "plan" in p:
            base_keys: tuple[str, ...] = ("plan", "plan_sha256", "pixel_size", *shared)
        else:
            base_keys = ("map", "size", "border", "map_seed", *shared)
    else:
        raw_path = t.get("path", "str", required=True)
        path = Path(os.path.expandvars(os.path.expanduser(raw_path)))
        if not path.is_absolute():
            path = (base_dir / path).resolve()
        if not path.exists():
            t.fail("path", f"no such {'log file' if kind == 'log' else 'bag'}: {path}")
        p["path"] = str(path)
        reader = t.raw("reader", {"max_usable_range": 20.0})
        rt = Table(source, f"{t.where}.reader", reader)
        r = {}
        if kind == "bag":
            p["bag"] = _bag_keys(t, path)
            for k, (vk, lo, lo_open, choices) in BAG_READER_KEYS.items():
                if rt.has(k):
                    r[k] = rt.get(k, vk, lo=lo, lo_open=lo_open, choices=choices)
        else:
            for k in READER_KEYS:
                if rt.has(k):
                    r[k] = rt.raw(k)
            for k in ("max_usable_range", "no_return_threshold", "max_range"):
                if k in r:
                    r[k] = rt.get(k, "float", lo=0, lo_open=True)
            if "min_range" in r:
                r["min_range"] = rt.get("min_range", "float", lo=0)
            for k in ("strict", "apply_laser_offset"):
                if k in r:
                    rt.get(k, "bool")
            for k in ("usable_range_rule", "no_return"):
                if k in r:
                    rt.get(k, "str", choices=("drop", "max"))
        rt.finish(optional=BAG_READER_KEYS if kind == "bag" else READER_KEYS)
        p["reader"] = r
        p["resolution"] = t.get("resolution", "float", 0.05, lo=0, lo_open=True)
        ext = t.raw("extent", None)
        if ext is not None:
            if not (
                isinstance(ext, list)
                and len(ext) == 4
                and all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in ext)
            ):
                t.fail("extent", f"must be [x0, y0, width, height] in metres, got {ext!r}")
            if ext[2] <= 0 or ext[3] <= 0:
                t.fail("extent", f"width and height must be > 0, got {ext!r}")
            ext = [float(x) for x in ext]
            res = p["resolution"]
            _too_many(t, "extent", round(ext[3] / res), round(ext[2] / res), max_cells, f"{ext} at {res} m a cell")
        p["extent"] = ext
        p["margin"] = t.get("margin", "float", 1.0, lo=0)
        p["sigma_cells"] = t.get("sigma_cells", "float", 3.0, lo=0, lo_open=True)
        p["pose_fraction"] = t.get("pose_fraction", "float", 1.0, sweep=True, lo=0, lo_open=True, hi=1)
        if t.has("beam_increment_deg"):
            if t.has("beam_step"):
                t.fail("beam_increment_deg", "give beam_step or beam_increment_deg, not both")
            p["beam_step"] = _steps_for_increment(t, kind, p)
        else:
            p["beam_step"] = t.get("beam_step", "int", 1, sweep=True, lo=1)
        bt = Table(source, f"{t.where}.benchmark", t.raw("benchmark", {}))
        p["benchmark"] = {
            "delta": _check_delta(bt, "delta", "haehnel"),
            "threshold": bt.get("threshold", "float", 0.20, lo=0, lo_open=True, hi=1),
            "prior": bt.get("prior", "float", 0.5, lo=0, lo_open=True, hi=1),
        }
        bt.finish()
        base_keys = ("path", "reader", "resolution", "extent", "margin", "benchmark")
        if kind == "bag":
            base_keys += ("bag",)
    t.finish()
    swept = [k for k in SWEEP_KEYS if isinstance(p.get(k), list)]
    out = []
    for combo in itertools.product(*[p[k] for k in swept]):
        q = dict(p)
        q.update(zip(swept, combo))
        suffix = "".join(f"-{SWEEP_KEYS[k]}{v:g}" for k, v in zip(swept, combo))
        cond = "".join(f"-{SWEEP_KEYS[k]}{v:g}" for k, v in zip(swept, combo) if k not in REPEAT_KEYS)
        base_sfx = "".join(f"-{SWEEP_KEYS[k]}{v:g}" for k, v in zip(swept, combo) if k in REPEAT_KEYS)
        out.append(
            DatasetSpec(
                name=name + suffix,
                entry=name,
                kind=kind,
                params=q,
                condition=name + cond,
                base=name + base_sfx,
                base_params={"kind": kind, **{k: q[k] for k in base_keys}},
                measurement_fraction=float(q["pose_fraction"]) / int(q["beam_step"]),
            )
        )
    return out


def _log_increment_deg(t: Table, kind: str, p: dict) -> float:
    """The angular increment (degrees) between neighbouring beams of the log or bag of a dataset entry, read
    with the entry's reader options; refused (naming ``path``) if the scans have no single increment."""
    try:
        if kind == "bag":
            from ogm_ppl.datasets.rosbag import bag_info

            info = bag_info(p["path"], p["bag"]["scan_topic"])
            incs = np.abs(np.degrees(np.asarray(info["angle_increment"], dtype=np.float64)))
        else:
            from ogm_ppl.datasets import read_carmen

            a = read_carmen(p["path"], **p["reader"]).scans.angles
            incs = np.abs(np.degrees(np.diff(np.atleast_2d(a), axis=1))).ravel()
    except (OSError, ValueError) as e:
        t.fail("path", f"cannot read the beam increment for beam_increment_deg ({type(e).__name__}: {e})")
    if incs.size == 0:
        t.fail("beam_increment_deg", "the scans have one beam each: there is no increment to thin")
    inc = float(np.median(incs))
    if not (inc > 0 and np.allclose(incs, inc, rtol=1e-3, atol=1e-9)):
        t.fail("beam_increment_deg", f"the scans' beams are not evenly spaced ({incs.min():g}-{incs.max():g} deg)")
    return inc


def _steps_for_increment(t: Table, kind: str, p: dict):
    """``beam_step`` for ``beam_increment_deg`` (a number or a sweep): the multiple of the log's increment,
    within 1 %; refused naming the nearest increment the log allows otherwise."""
    wanted = t.get("beam_increment_deg", "float", sweep=True, lo=0, lo_open=True)
    inc = _log_increment_deg(t, kind, p)
    steps = []
    for v in np.atleast_1d(wanted):
        k = round(float(v) / inc)
        if k < 1 or abs(k * inc - v) > 0.01 * v:
            near = max(k, 1) * inc
            t.fail(
                "beam_increment_deg",
                f"{v:g} degrees is not a multiple of the scans' {inc:g}-degree increment (nearest: {near:g})",
            )
        steps.append(k)
    return steps if isinstance(wanted, list) else steps[0]


def _bag_keys(t: Table, path: Path) -> dict:
    """The topics and pose options of a ``kind = "bag"`` entry (module docstring), checked here."""
    from ogm_ppl.datasets.rosbag import bag_kind

    if bag_kind(path) is None:
        t.fail("path", f"not a ROS bag (a ROS 1 .bag file, or a ROS 2 bag folder or its .db3 / .mcap): {path}")
    b: dict = {"scan_topic": t.get("scan_topic", "str", required=True)}
    pose = t.get("pose_topic", "str", None)
    tf = t.get("tf", "bool", False)
    if (pose is None) == (not tf):
        t.fail("pose_topic" if pose is not None else "tf", "give pose_topic or tf = true, one of them")
    b["pose_topic"], b["tf"] = pose, tf
    if t.has("map_frame") and not tf:
        t.fail("map_frame", "applies to tf = true")
    b["map_frame"] = t.get("map_frame", "str", "map")
    off = t.raw("laser_offset", [0.0, 0.0, 0.0])
    if not (
        isinstance(off, list)
        and len(off) == 3
        and all(isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x) for x in off)
    ):
        t.fail("laser_offset", f"must be [x, y, yaw] (metres, radians), got {off!r}")
    if tf and any(off):
        t.fail("laser_offset", "applies to pose_topic; with tf = true the mounting comes from /tf_static")
    b["laser_offset"] = [float(x) for x in off]
    b["pose_tolerance"] = t.get("pose_tolerance", "float", 0.1, lo=0)
    return b


def _algorithm(source: str, i: int, a) -> AlgorithmSpec:
    """An ``[[algorithms]]`` entry: ``name``, ``kind`` (a registered map method, :mod:`ogm_ppl.methods`)
    and that method's parameters, validated by its parameter dataclass."""
    from ogm_ppl.methods import ParamError, get_method, method_names

    t, name = named_entry(source, "algorithms", i, a)
    kind = t.get("kind", "str", required=True, choices=tuple(method_names()))
    method = get_method(kind)
    values = {k: t.raw(k) for k in t.table if k not in ("name", "kind")}
    try:
        params = method.parse(values)
    except ParamError as e:
        t.fail(e.key, e.message)
    return AlgorithmSpec(name, kind, asdict(params))


def parse_map_spec(data: dict, source: str = "<dict>", base_dir: str | os.PathLike = ".") -> ExperimentSpec:
    """Validate a spec of the kind ``map`` given as a dict (the parsed TOML); ``source`` names it in errors.
    :func:`ogm_ppl.experiment.parse_spec` reads any kind."""
    if not isinstance(data, dict):
        raise SpecError(f"{source}: a spec is a table, got {type(data).__name__}")
    unknown = sorted(set(data) - {"experiment", "datasets", "algorithms", "metrics", "output"})
    if unknown:
        raise SpecError(
            f"{source}: {unknown[0]}: unknown table (known: experiment, datasets, algorithms, metrics, output)"
        )
    e = Table(source, "experiment", data.get("experiment", {}))
    stem = Path(source).stem if source != "<dict>" else "experiment"
    if e.has("name"):
        name = e.get("name", "str")
        check_name(e, name)
    else:
        name = e.get("name", "str", stem)
    seed = e.get("seed", "int", 0, lo=0)
    max_cells = e.get("max_cells", "int", MAX_CELLS, lo=1)
    e.get("kind", "str", "map", choices=("map",))
    description = e.raw("description", "")
    if not isinstance(description, str):
        e.fail("description", "must be a string")
    e.finish()
    raw_ds = data.get("datasets")
    if not isinstance(raw_ds, list) or not raw_ds:
        raise SpecError(f"{source}: datasets: at least one [[datasets]] entry is required")
    raw_alg = data.get("algorithms")
    if not isinstance(raw_alg, list) or not raw_alg:
        raise SpecError(f"{source}: algorithms: at least one [[algorithms]] entry is required")
    datasets: list[DatasetSpec] = []
    entries: set[str] = set()
    for i, d in enumerate(raw_ds):
        ds = _dataset_entry(source, Path(base_dir), i, d, seed, max_cells)
        if ds[0].entry in entries:
            raise SpecError(f"{source}: datasets[{i}].name: {ds[0].entry!r} is used twice")
        entries.add(ds[0].entry)
        datasets += ds
    names = [d.name for d in datasets]
    dup = next((n for n in names if names.count(n) > 1), None)
    if dup:
        raise SpecError(f"{source}: datasets: two entries expand to the dataset name {dup!r}; rename one")
    algorithms = [_algorithm(source, i, a) for i, a in enumerate(raw_alg)]
    anames = [a.name for a in algorithms]
    dup = next((n for n in anames if anames.count(n) > 1), None)
    if dup:
        raise SpecError(f"{source}: algorithms: the name {dup!r} is used twice")
    m = Table(source, "metrics", data.get("metrics", {}))
    thr = m.raw("thresholds", 99)
    if isinstance(thr, int) and not isinstance(thr, bool):
        if thr < 1:
            m.fail("thresholds", f"must be >= 1, got {thr}")
        thresholds = tuple(np.round(np.linspace(0.01, 0.99, thr), 10).tolist()) if thr > 1 else (0.5,)
    elif (
        isinstance(thr, list)
        and thr
        and all(isinstance(x, (int, float)) and not isinstance(x, bool) and 0 <= x < 1 for x in thr)
    ):
        thresholds = tuple(float(x) for x in thr)
    else:
        m.fail("thresholds", f"must be a count or a list of numbers in [0, 1), got {thr!r}")
    scores = m.raw("scores", ["f1", "auc", "max_precision"])
    if not isinstance(scores, list) or any(s not in SCORES for s in scores):
        m.fail("scores", f"must be a list of {', '.join(map(repr, SCORES))}, got {scores!r}")
    metrics = MetricsSpec(
        mask=m.get("mask", "str", "auto", choices=("auto", "all", "known", "near_mapped")),
        near_mapped_distance=m.get("near_mapped_distance", "float", 10.0, lo=0),
        touched_only=m.get("touched_only", "bool", True),
        thresholds=thresholds,
        scores=tuple(scores),
    )
    m.finish()
    o = Table(source, "output", data.get("output", {}))
    fthr = o.raw("fpfn_thresholds", [0.1, 0.2, 0.6])
    if not isinstance(fthr, list) or not all(
        isinstance(x, (int, float)) and not isinstance(x, bool) and 0 <= x < 1 for x in fthr
    ):
        o.fail("fpfn_thresholds", f"must be a list of numbers in [0, 1), got {fthr!r}")
    output = OutputSpec(
        maps=o.get("maps", "bool", True),
        figures=o.get("figures", "bool", True),
        fpfn=o.get("fpfn", "str", "first", choices=("first", "all", "none")),
        fpfn_thresholds=tuple(float(x) for x in fthr),
        dpi=o.get("dpi", "int", 100, lo=20, hi=600),
    )
    o.finish()
    return ExperimentSpec(
        name,
        seed,
        description,
        tuple(datasets),
        tuple(algorithms),
        metrics,
        output,
        source,
        json.loads(json.dumps(data, default=str)),
        max_cells,
    )
