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
    [[datasets]]        kind = an input kind (*required*; ogm_ppl.inputs: "simulated", "log", "bag", "npz", or a
                        kind of one's own that reads a file), name (*required*, [A-Za-z0-9_.-]+); the kind's
                        options are checked by its options dataclass, each error naming the key
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
                        reader [{max_usable_range = 20.0}] (the kind's reader options, ogm_ppl.inputs.LogOptions:
                        strict, max_usable_range, usable_range_rule, no_return, no_return_threshold, min_range,
                        max_range, messages, apply_laser_offset), resolution [0.05],
                        extent [x0, y0, width, height] metres (else the log's extent + margin [1.0]),
                        sigma_cells [3.0] (the models' range noise), pose_fraction [1.0], beam_step [1]
                        or beam_increment_deg (the same as a multiple of the log's increment),
                        benchmark [{delta = "haehnel", threshold = 0.20, prior = 0.5}]
      bag:              a ROS bag (ogm_ppl.datasets.read_bag): path (*required*; a .bag file or a ROS 2 bag
                        folder / .db3 / .mcap), scan_topic (*required*), pose_topic or tf = true (one is
                        *required*), map_frame ["map"; tf only], laser_offset [[0, 0, 0]] (x, y, yaw of the
                        laser in the robot frame; pose_topic only), pose_tolerance [0.1] (s), reader
                        [{max_usable_range = 20.0}] (ogm_ppl.inputs.BagOptions: strict, max_usable_range,
                        usable_range_rule, no_return, no_return_threshold, min_range, max_range, widen), and the
                        keys of log
      npz:              an ogm_ppl dataset file: path (*required*) and the keys of log but reader (a dataset
                        file's scans are read already); scored, as a log, against its benchmark map
      a kind of one's own that reads a file: its options at the entry (those of group "reader" in its
                        reader table) and the keys of log
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
    [metrics]           mask ["auto": "known" for simulated, "near_mapped" for data read from a file; "all":
                        every cell;
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

import itertools
import json
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

SWEEP_KEYS = {"map_seed": "m", "seed": "s", "pose_fraction": "pf", "beam_step": "bs"}
REPEAT_KEYS = ("map_seed", "seed")
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
        """The mask scored on a dataset of the input kind ``dataset_kind``: :attr:`mask`, ``"auto"`` read as
        ``"near_mapped"`` for data read from a file (a log, a bag: scored on their benchmark map) and ``"known"``
        for simulated data."""
        if self.mask != "auto":
            return self.mask
        from ogm_ppl.inputs import get_input_kind

        return "near_mapped" if get_input_kind(dataset_kind).reads_file else "known"


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


def _resolve(raw: str, base_dir: Path) -> Path:
    """A spec's path: ``~`` and ``$VARS`` expanded, relative to the spec file's folder."""
    path = Path(os.path.expandvars(os.path.expanduser(raw)))
    return path if path.is_absolute() else (base_dir / path).resolve()


def _parse_options(kind, values: dict, table_of):
    """``kind``'s options from ``values``; an error names the key in the table ``table_of(key)`` holds it."""
    from ogm_ppl.options import ParamError

    try:
        return kind.parse(values)
    except ParamError as e:
        table_of(e.key).fail(e.key, e.message)


def _sweep(t: Table, kind, key: str, values: list) -> list:
    """The values of a swept option, each checked by the option's kind (an error names ``key[i]``)."""
    from ogm_ppl.options import _Bad, param_fields

    if not values:
        t.fail(key, "an empty list sweeps over nothing")
    check = {name: k for name, k, _, _ in param_fields(kind.options)}[key]
    out = []
    for i, v in enumerate(values):
        try:
            out.append(check.value(v))
        except _Bad as e:
            t.fail(f"{key}[{i}]", str(e))
    if len(set(out)) != len(out):
        t.fail(key, f"lists a value twice: {values!r}")
    return out


def _scene_keys(t: Table, kind, name: str, seed: int, base_dir: Path, max_cells: int) -> tuple[dict, tuple[str, ...]]:
    """The parameters of a simulated dataset: the kind's options (:class:`~ogm_ppl.inputs.SimulatedOptions`) as
    used, sweeps as lists, a plan's path resolved and its digest; and the keys its base (scene and route)
    depends on."""
    from ogm_ppl.inputs.simulated import plan_digest

    names = kind.option_names()
    values = {k: t.raw(k) for k in names if t.has(k)}
    t.used.update(names)
    values.setdefault("seed", derive_seed(seed, "dataset", name, bits=32))
    if values.get("plan") is not None:  # a floor plan of your own, relative to the spec file
        raw = _parse_options(kind, {"plan": values["plan"]}, lambda k: t).plan
        path = _resolve(raw, base_dir)
        if not path.is_file():
            t.fail("plan", f"no such plan file: {path}")
        values["plan"] = str(path)
    sweeps = {k: _sweep(t, kind, k, values[k]) for k in SWEEP_KEYS if isinstance(values.get(k), list)}
    for combo in itertools.product(*sweeps.values()):  # every combination obeys the rules between options
        options = _parse_options(kind, values | dict(zip(sweeps, combo)), lambda k: t)
    p = options.effective() | sweeps
    if "plan" in p:
        p["plan_sha256"] = plan_digest(p["plan"])  # a changed plan is a new dataset
        _check_plan(t, p, max_cells)
        return p, ("plan", "plan_sha256", "pixel_size", "resolution", "seed", "poses", "max_range_cells")
    rows, cols = p["size"]
    _too_many(t, "size", rows, cols, max_cells, f"size = {p['size']}")
    return p, ("map", "size", "border", "map_seed", "resolution", "seed", "poses", "max_range_cells")


def _file_keys(t: Table, kind, source: str, base_dir: Path, max_cells: int) -> tuple[dict, tuple[str, ...]]:
    """The parameters of a dataset read from a file: ``path`` (resolved, of the entry's kind), the kind's own
    options given at the entry (under the kind's name: a bag's topics and pose source) and in its ``reader``
    table, the grid, the sparsity and the benchmark map; and the keys its base (the read log) depends on."""
    from ogm_ppl.inputs import InputError, check_readable

    path = _resolve(t.get("path", "str", required=True), base_dir)
    if not path.exists():
        t.fail("path", f"no such {kind.noun}: {path}")
    if kind.detect is not None and not kind.detect_last:
        try:
            head = b"" if path.is_dir() else check_readable(path)
        except InputError as e:
            t.fail("path", str(e))
        if not kind.detect(path, head):
            t.fail("path", f"not a {kind.noun} ({kind.what}): {path}")
    p: dict = {"path": str(path)}
    own, read = kind.option_names(""), kind.option_names("reader")
    values = {k: t.raw(k) for k in own if t.has(k)}
    t.used.update(own)
    default_reader = {"max_usable_range": 20.0} if "max_usable_range" in read else {}
    rt = Table(source, f"{t.where}.reader", t.raw("reader", default_reader))
    for k in rt.table:
        if k not in read:
            known = f"known here: {', '.join(sorted(read))}" if read else f"a {kind.noun} takes no reader options"
            rt.fail(k, f"unknown key ({known})")
    options = _parse_options(kind, values | rt.table, lambda k: rt if k in read else t)
    if own:
        p[kind.name] = {k: getattr(options, k) for k in values}
    p["reader"] = {k: getattr(options, k) for k in rt.table}
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
        p["beam_step"] = _steps_for_increment(t, kind, path, options)
    else:
        p["beam_step"] = t.get("beam_step", "int", 1, sweep=True, lo=1)
    bt = Table(source, f"{t.where}.benchmark", t.raw("benchmark", {}))
    p["benchmark"] = {
        "delta": _check_delta(bt, "delta", "haehnel"),
        "threshold": bt.get("threshold", "float", 0.20, lo=0, lo_open=True, hi=1),
        "prior": bt.get("prior", "float", 0.5, lo=0, lo_open=True, hi=1),
    }
    bt.finish()
    return p, ("path", "reader", "resolution", "extent", "margin", "benchmark", *((kind.name,) if own else ()))


def dataset_kinds() -> tuple[str, ...]:
    """The input kinds a ``[[datasets]]`` entry may name: ``simulated`` and every kind that reads a file
    (:mod:`ogm_ppl.inputs`; kinds of one's own included, once their modules are imported)."""
    from ogm_ppl.extensions import load_extensions
    from ogm_ppl.inputs import get_input_kind, input_kinds

    load_extensions()
    return ("simulated", *[k for k in input_kinds() if get_input_kind(k).reads_file])


def _dataset_entry(source: str, base_dir: Path, i: int, d, seed: int, max_cells: int = MAX_CELLS) -> list[DatasetSpec]:
    from ogm_ppl.inputs import get_input_kind

    t, name = named_entry(source, "datasets", i, d)
    kind = get_input_kind(t.get("kind", "str", required=True, choices=dataset_kinds()))
    if kind.reads_file:
        p, base_keys = _file_keys(t, kind, source, base_dir, max_cells)
    else:
        p, base_keys = _scene_keys(t, kind, name, seed, base_dir, max_cells)
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
                kind=kind.name,
                params=q,
                condition=name + cond,
                base=name + base_sfx,
                base_params={"kind": kind.name, **{k: q[k] for k in base_keys}},
                measurement_fraction=float(q["pose_fraction"]) / int(q["beam_step"]),
            )
        )
    return out


def _log_increment_deg(t: Table, kind, path: Path, options) -> float:
    """The angular increment (degrees) between neighbouring beams of the scans of a dataset entry, read with
    the entry's options; refused (naming ``path``) if the scans have no single increment."""
    from ogm_ppl.inputs import read_input

    try:
        a = read_input(kind.name, path, options).scans.angles
        incs = np.abs(np.degrees(np.diff(np.atleast_2d(a), axis=1))).ravel()
    except (OSError, ValueError) as e:
        t.fail("path", f"cannot read the beam increment for beam_increment_deg ({type(e).__name__}: {e})")
    if incs.size == 0:
        t.fail("beam_increment_deg", "the scans have one beam each: there is no increment to thin")
    inc = float(np.median(incs))
    if not (inc > 0 and np.allclose(incs, inc, rtol=1e-3, atol=1e-9)):
        t.fail("beam_increment_deg", f"the scans' beams are not evenly spaced ({incs.min():g}-{incs.max():g} deg)")
    return inc


def _steps_for_increment(t: Table, kind, path: Path, options):
    """``beam_step`` for ``beam_increment_deg`` (a number or a sweep): the multiple of the scans' increment,
    within 1 %; refused naming the nearest increment the scans allow otherwise."""
    wanted = t.get("beam_increment_deg", "float", sweep=True, lo=0, lo_open=True)
    inc = _log_increment_deg(t, kind, path, options)
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
