"""``ogm-ppl map INPUT --out DIR``: an occupancy grid map of a log, a bag or a dataset file by any registered
map method, with checkpoints, a PNG, a ROS map and a report."""

from __future__ import annotations

import dataclasses
import json
import math
import sys
import time
import warnings
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ogm_ppl.grid import MAX_CELLS, Grid
from ogm_ppl.io import StagedFolder, atomic_write_text
from ogm_ppl.methods import (
    MapProblem,
    ParamError,
    RunContext,
    get_method,
    method_names,
    methods,
)

if TYPE_CHECKING:
    from ogm_ppl.methods import MapMethod
from ogm_ppl.cli._checkpoints import (
    CHECKPOINTS,
    _checkpoint_root,
    _drop_own_checkpoints,
    _online_map,
)
from ogm_ppl.cli._common import (
    CLIError,
    _finite,
    _fmt_s,
    _jsonable,
    _nonneg_float,
    _nonneg_int,
    _one_line,
    _plural,
    _pos_float,
    _pos_int,
    _prepare_out_dir,
    _probability,
    _refuse_out_over_inputs,
    _seed,
    _size,
    _steps,
    _version,
)
from ogm_ppl.cli._input import (
    _add_bag_options,
    _add_reader_options,
    _Input,
    _make_grid,
    _read_input,
    _scan_range,
    _scans_on_grid,
)
from ogm_ppl.cli._map_files import (
    MAP_FORMAT,
    MAP_FORMAT_VERSION,
    _atomic_savez,
    _report_md,
    save_map_png,
)

#: flags of ``ogm-ppl map`` that set a method parameter: flag -> (parameter, argparse dest)
METHOD_FLAGS = {
    "--delta": ("delta", "delta"),
    "--prior": ("prior", "prior"),
    "--lambda": ("lam", "lam"),
    "--sigma": ("sigma_cells", "sigma"),
    "--sensor": ("sensor", "sensor"),
    "--sweeps": ("sweeps", "sweeps"),
    "--warmup": ("burn_in", "warmup"),
    "--patch": ("patch", "patch"),
    "--threads": ("threads", "threads"),
}
#: the entries ``ogm-ppl map`` writes in its folder (an input there under one of these names is refused)
MAP_OUTPUTS = ("map.npz", "map.png", "snapshots.npz", "ros", "report.json", "report.md", CHECKPOINTS)
#: the command line's own defaults (``--help`` states them): sweeps, burn-in = sweeps // 10, and the
#: thesis's cell prior 0.234 for the prior "independent"
CLI_SWEEPS, CLI_LAMBDA = 200, 0.234


def add_parser(sub) -> None:
    """The ``map`` subcommand's options."""
    # --------------------------------------------------------------------------------- map
    m = sub.add_parser(
        "map",
        help="occupancy grid map of a CARMEN log, a ROS bag or a dataset file",
        description="Map INPUT (a CARMEN log, plain or gzip, a ROS 1 or ROS 2 bag, or an ogm_ppl dataset .npz) into "
        "DIR: map.npz, map.png, ros/map.yaml + ros/map.pgm (+ sidecar), "
        "report.json, report.md. A sampling method (gibbs, patch, ...) checkpoints its chains in DIR/.checkpoints "
        "(every checkpoint_every sweeps, and on Ctrl-C): rerunning the same command resumes them.",
    )
    m.add_argument(
        "input",
        type=Path,
        metavar="INPUT",
        help="a CARMEN log (.log / .log.gz), a ROS bag (.bag, a ROS 2 bag folder, .db3, .mcap) or a dataset .npz",
    )
    m.add_argument("--out", type=Path, required=True, metavar="DIR", help="output directory (created)")
    m.add_argument(
        "--resolution",
        type=_pos_float,
        metavar="M",
        help="cell size in metres (default 0.05; for a dataset file with a grid, its resolution)",
    )
    ext = m.add_mutually_exclusive_group()
    ext.add_argument(
        "--size",
        type=_pos_int,
        nargs=2,
        metavar=("W", "H"),
        help="grid of W columns x H rows cells with its lower-left corner at --origin (default "
        "origin 0 0); every pose must lie inside",
    )
    ext.add_argument(
        "--auto-extent",
        action="store_true",
        help="(default) a grid covering every pose and hit end point plus --margin; for a dataset "
        "file with a grid and no --resolution/--margin/--origin, that grid",
    )
    m.add_argument(
        "--origin",
        type=_finite,
        nargs=2,
        metavar=("X", "Y"),
        help="world coordinates (metres) of the grid's lower-left corner",
    )
    m.add_argument(
        "--crop",
        action="store_true",
        help="with --size: map the part of the data the grid covers, keeping the scans whose pose lies on "
        "it (beams reaching beyond it are clipped at its edge) instead of refusing the others",
    )
    m.add_argument(
        "--scans",
        type=_scan_range,
        metavar="A:B",
        help="map the scans A to B - 1 of the input (0-based, A < B, either end may be left open: 100:400, :400, "
        "100:; an end past the last scan stops there), counted before --pose-step / --pose-fraction thin them; "
        "the report lists what each step kept",
    )
    m.add_argument(
        "--margin",
        type=_nonneg_float,
        metavar="M",
        help="metres added on every side of the automatic extent (default 1.0)",
    )
    m.add_argument(
        "--max-cells",
        type=_pos_int,
        default=MAX_CELLS,
        metavar="N",
        help=f"refuse grids of more than N cells (default {MAX_CELLS:,})",
    )
    m.add_argument(
        "--method",
        default="ogm",
        metavar="NAME",
        help="map method (default ogm), any registered one (ogm-ppl methods lists them with their "
        "parameters): " + ", ".join(method_names()),
    )
    m.add_argument(
        "--param",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="set a parameter of the method (repeatable), e.g. --param scan=random; 'ogm-ppl methods NAME' lists them",
    )
    m.add_argument(
        "--delta",
        metavar="NAME",
        help="parameter delta: the update term of the log-odds methods, any name delta_by_name "
        "knows (haehnel, elfes_thesis, p21_thesis, p21, moravec_opt, ...); default: haehnel "
        "for ogm, p21 for p21, elfes_thesis for elfes",
    )
    m.add_argument(
        "--prior",
        metavar="NAME",
        help="parameter prior of the model-based methods (gibbs, patch, ...; of ogm: the cells' "
        "prior occupancy, a number): 'independent' (each "
        "cell occupied with probability --lambda, the default) or a learned prior "
        "KIND:CORPUS (ogm_ppl.priors.prior_by_name), e.g. mrf:houseexpo, patch3:houseexpo, "
        "border:houseexpo, border1:houseexpo",
    )
    m.add_argument(
        "--lambda",
        dest="lam",
        type=_probability,
        metavar="P",
        help=f"parameter lam: cell prior occupancy of the independent prior (default {CLI_LAMBDA}, the thesis's value)",
    )
    m.add_argument(
        "--sigma",
        type=_pos_float,
        metavar="CELLS",
        help="parameter sigma_cells: range noise of the sensor model in cells (the Gaussian range model's "
        "standard deviation) "
        "(default: the dataset's simulation sigma if recorded, else 1.0 cell, about the "
        "scatter of a corrected real log at 5 cm)",
    )
    m.add_argument(
        "--sensor",
        metavar="NAME",
        help="parameter sensor of the model-based methods: the forward sensor model by name, KIND or "
        "KIND:KEY=VALUE,... (ogm_ppl.sensors.sensor_by_name; default gaussian, the Gaussian range model of "
        "--sigma; a kind of your own registered with register_sensor in a module named in $OGM_PPL_METHODS, "
        "its factory's keyword parameters its options)",
    )
    m.add_argument(
        "--threads",
        type=_pos_int,
        metavar="N",
        help="parameter threads of gibbs: chromatic tile sweeps on N of numba's threads (exact; one chain "
        "whatever N, another than the serial kernel's; priors with a compiled face); of ogm (p21, elfes): the rays "
        "walked on N threads (the same map for any N)",
    )
    m.add_argument(
        "--sweeps",
        type=_pos_int,
        metavar="N",
        help=f"parameter sweeps: MCMC sweeps counted in the marginals (default {CLI_SWEEPS})",
    )
    m.add_argument(
        "--warmup",
        type=_nonneg_int,
        metavar="N",
        help="parameter burn_in: MCMC sweeps run before counting (default: sweeps // 10)",
    )
    m.add_argument(
        "--patch",
        metavar="SHAPE",
        help="parameter patch: of gibbs (PatchGibbs instead of CellGibbs) and patch "
        "(default 3x3): HxW, an int L (a run of L cells), 'plus' or 'square'",
    )
    m.add_argument("--seed", type=_seed, default=0, metavar="S", help="random seed (0 to 2^62, default 0)")
    m.add_argument(
        "--online",
        action="store_true",
        help="replay the scans one at a time: into an online single-cell Gibbs chain (--method gibbs; "
        "ogm_ppl.inference.online.OnlineMap): focused sweeps after each scan, then --warmup and --sweeps full "
        "sweeps; or into the amortised guide's map (--method amortised; OnlineGuideMap): each scan recomputes "
        "the cells its rays' changes reach, the same map as without --online to float32 rounding",
    )
    m.add_argument(
        "--snapshots",
        type=_pos_int,
        metavar="K",
        help="with --online: also write snapshots.npz, the marginals after every K-th scan (K: at most the scans)",
    )
    _add_reader_options(m, carmen_only=True)
    _add_bag_options(m)
    m.add_argument(
        "--thresholds",
        choices=("ros1", "nav2"),
        default="ros1",
        help="occupied/free thresholds of the ROS map: ros1 (0.65/0.196, default) or nav2 (0.65/0.25)",
    )
    m.add_argument(
        "--unobserved",
        choices=("unknown", "predict"),
        default="unknown",
        help="cells no ray reached, in map.png and the ROS map: unknown (grey / -1, default; what a planner "
        "should not drive into) or predict (drawn and thresholded from their probability, as every other cell: "
        "what a correlated prior predicts there). map.npz always holds every cell's probability",
    )


def _method_params(args) -> tuple[MapMethod, object]:
    """The method of ``--method`` and its parameters: the flags of :data:`METHOD_FLAGS` that were given,
    then the command line's defaults (:data:`CLI_SWEEPS`, burn-in ``sweeps // 10``, :data:`CLI_LAMBDA`)
    where the method has those parameters, then ``--param KEY=VALUE`` (command-line strings)."""
    try:
        method = get_method(args.method)
    except ParamError as e:
        raise CLIError(f"argument --method: {e.message}") from None
    names = method.param_names()
    values: dict = {}
    source: dict = {}
    for flag, (key, dest) in METHOD_FLAGS.items():
        v = getattr(args, dest)
        if v is None:
            continue
        if key not in names:
            having = [m.name for m in methods() if key in m.param_names() and m.alias_of is None]
            raise CLIError(
                f"{flag} sets the parameter {key!r} of {', '.join(having) or 'no method'}; "
                f"--method {method.name} has none"
            )
        values[key], source[key] = v, f"argument {flag}"
    for item in args.param:
        key, eq, v = item.partition("=")
        if not eq or not key.strip():
            raise CLIError(f"argument --param: expected KEY=VALUE, got {item!r}")
        key = key.strip()
        if key in values:
            raise CLIError(f"--param {key} repeats {source[key]}")
        values[key], source[key] = v, f"--param {key}"
    if "sweeps" in names:
        values.setdefault("sweeps", str(CLI_SWEEPS))
    if "burn_in" in names and "burn_in" not in values:
        try:
            values["burn_in"] = str(int(values["sweeps"]) // 10)
        except ValueError:
            pass  # a bad --param sweeps is reported below
    if "lam" in names and values.get("prior", method.default_params().prior) == "independent":
        values.setdefault("lam", str(CLI_LAMBDA))
    text = {k: str(v) for k, v in values.items()}
    try:
        params = method.parse(text, text=True)
    except ParamError as e:
        where = source.get(e.key, f"parameter {e.key}")
        raise CLIError(f"{where}: {e.message}") from None
    patch = getattr(params, "patch", None)
    if isinstance(patch, int) and patch > 1 and math.isqrt(patch) ** 2 == patch:
        side = math.isqrt(patch)
        print(
            f"ogm-ppl: note: --patch {patch} is a run of {patch} cells in one row; square {side} x {side} patches "
            f"(L = {patch} in the thesis) are --patch {side}x{side}",
            file=sys.stderr,
        )
    return method, params


def _compute_map(
    args, method: MapMethod, params, inp: _Input, grid: Grid, times: dict
) -> tuple[np.ndarray, np.ndarray, dict]:
    """``(probabilities K float64, observed K bool, details)`` of ``method``: the marginals averaged over
    its ``chains`` (chain ``c`` seeded ``--seed + c``); warnings become lines ``ogm-ppl: warning: ...``."""
    sigma = float(inp.settings.get("sigma_cells") or 0) or None
    problem = MapProblem(grid, inp.scans, sigma_cells=sigma)
    if getattr(args, "online", False):
        return _online_map(args, method, params, problem, times)
    chains = int(getattr(params, "chains", 1))
    root = _checkpoint_root(args, params, inp, grid)
    probs, ray, total = [], None, 0.0
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        from ogm_ppl.inference._kernels import quiet_numba_ir_check

        quiet_numba_ir_check()
        for c in range(chains):
            where = f"ogm-ppl map {args.input}"
            folder = None if root is None else root / f"chain-{c}"
            if folder is not None and (folder / "gibbs.npz").exists():
                print(f"ogm-ppl: chain {c} resumes from its checkpoint in {folder}", file=sys.stderr)
            ctx = RunContext(seed=args.seed + c, checkpoint_dir=folder, cache_dir=args.out, progress=True, where=where)
            try:
                result = method.run(params, problem, ctx)
            except KeyboardInterrupt as e:
                if root is not None and any(root.glob("chain-*/gibbs.npz")):
                    raise KeyboardInterrupt(f"checkpoints kept in {root}: the same command resumes from them") from e
                raise
            assert result.probabilities is not None  # no stop_after on the command line
            probs.append(result.probabilities)
            ray = result.seconds["ray_cast"] if ray is None else ray
            total += result.seconds["map"] or 0.0
    for w in {str(w.message): w for w in caught}.values():
        print(f"ogm-ppl: warning: {_one_line(w.message)}", file=sys.stderr)  # type: ignore[arg-type]
    times["ray_cast_s"], times["map_s"] = ray, total
    details = {**dataclasses.asdict(params), **result.details, "seed": args.seed, "chains": chains}
    return np.mean(probs, axis=0) if chains > 1 else probs[0], result.observed, details


#: where ``map`` keeps a sampling method's checkpoints, inside ``--out`` (removed once the map is written)


def _counts(inp: _Input) -> dict:
    s = inp.scans
    src = inp.log if inp.log is not None else inp.bag
    # the reader counts the beams of the scans it read: of those mapped unless --scans / --crop kept some
    present = int(src.counts["beams"]) if src is not None and not inp.selection else int(s.num_readings)
    c: dict[str, int | dict[str, int] | list[str]] = {
        "scans": s.num_scans,
        "beams": present,
        "valid_beams": s.num_valid,
        "dropped_beams": present - s.num_valid,
        "max_range_readings": int(s.is_max.sum()),
    }
    if inp.selection:  # --scans / --crop: the reader's counts below are of every scan read
        c["selection"] = list(inp.selection)
    if inp.log is not None:
        for k in ("no_return", "beyond_usable", "below_min"):
            c[k] = int(inp.log.counts.get(k, 0))
        c["bad_lines"] = len(inp.log.bad_lines)
        c["skipped_message_types"] = dict(inp.log.skipped_types)
    if inp.bag is not None:
        for k in ("no_return", "beyond_usable", "below_min", "scans_read", "no_pose", "pose_samples"):
            c[k] = int(inp.bag.counts.get(k, 0))
        c["bad_messages"] = len(inp.bag.bad_messages)
    return c


def _scores(probs, observed, inp: _Input, grid: Grid) -> dict | None:
    if inp.truth is None or inp.grid != grid:
        return None
    from ogm_ppl.metrics import best_f1, near_mapped_mask, roc_auc

    truth = np.asarray(inp.truth).astype(bool).ravel()
    mask = near_mapped_mask(observed.reshape(grid.shape), 10.0).ravel()
    if truth[mask].all() or not truth[mask].any():
        return None
    f1, thr = best_f1(probs, truth, mask=mask)
    return {
        "best_f1": f1,
        "best_threshold": thr,
        "roc_auc": roc_auc(probs, truth, mask=mask),
        "mask": "cells within 10 cells of an observed cell (Fig. 6.16b)",
    }


def cmd_map(args) -> dict:
    """``ogm-ppl map``: read, grid, map, write; returns the report."""
    method, params = _method_params(args)
    _refuse_out_over_inputs(args.out, [args.input], writes=MAP_OUTPUTS)
    created = not args.out.exists()
    _prepare_out_dir(args.out)
    try:
        return _map(args, method, params)
    except BaseException:
        if created and args.out.is_dir() and not any(args.out.iterdir()):
            args.out.rmdir()  # leave no empty directory behind after an error
        raise


def _map(args, method, params) -> dict:
    times: dict = {}
    with _steps(4, f"ogm-ppl map ({args.method})") as bar:
        bar.set_postfix_str("reading")
        t0 = time.perf_counter()
        inp = _read_input(args)
        times["read_s"] = time.perf_counter() - t0
        bar.update()
        bar.set_postfix_str("grid")
        grid = _make_grid(args, inp)
        inp = _scans_on_grid(args, inp, grid)
        bar.update()
        bar.set_postfix_str("mapping")
        if getattr(args, "snapshots", None) is not None and not getattr(args, "online", False):
            raise CLIError("--snapshots needs --online")
        if getattr(args, "snapshots", None) is not None and args.snapshots > inp.scans.num_scans:
            n = inp.scans.num_scans  # else no snapshot at all, and no snapshots.npz
            raise CLIError(f"--snapshots {args.snapshots}: more than the {n} scans mapped (at most {n})")
        probs, observed, details = _compute_map(args, method, params, inp, grid, times)
        snapshots = details.pop("_snapshots", None)
        bar.update()
        bar.set_postfix_str("writing")
        t0 = time.perf_counter()
        settings = _jsonable({k: v for k, v in vars(args).items() if k not in ("traceback",)})
        settings["method_details"] = _jsonable(details)
        # the folder is all old or all new outputs, whatever interrupts this; a failed write names the file in it
        with StagedFolder(args.out) as stage:
            ros = _write_map(args, stage.path, probs, observed, grid, settings, snapshots)
            times["write_s"] = time.perf_counter() - t0
            bar.update()
            report = _report(args, method, inp, grid, probs, observed, details, times, ros, snapshots, settings)
            atomic_write_text(stage.path / "report.json", json.dumps(_jsonable(report), indent=2))
            atomic_write_text(stage.path / "report.md", _report_md(report))
    _drop_own_checkpoints(args, _checkpoint_root(args, params, inp, grid))
    return report


def _write_map(args, out: Path, probs, observed, grid: Grid, settings: dict, snapshots):
    """``map.npz``, ``snapshots.npz`` (``--online --snapshots``), ``map.png`` and the ROS map in ``out``; returns
    the ROS map's files."""
    from ogm_ppl.rosmap import save_ros_map

    _atomic_savez(
        out / "map.npz",
        format=np.array(MAP_FORMAT),
        format_version=np.int64(MAP_FORMAT_VERSION),
        probabilities=probs.reshape(grid.shape),
        observed=observed.reshape(grid.shape),
        grid=np.array([grid.rows, grid.cols, grid.resolution, *grid.origin], dtype=float),
        method=np.array(args.method),
        settings=np.array(json.dumps(settings)),
    )
    if snapshots:
        _atomic_savez(
            out / "snapshots.npz",
            scans=np.array([n for n, _ in snapshots], dtype=np.int64),
            probabilities=np.stack([p.reshape(grid.shape) for _, p in snapshots]),
        )
    shown = observed if args.unobserved == "unknown" else np.ones_like(observed)
    save_map_png(out / "map.png", probs, shown, grid)
    (out / "ros").mkdir(exist_ok=True)
    ros = save_ros_map(out / "ros" / "map.yaml", probs, grid, unknown=~shown, thresholds=args.thresholds)
    assert ros.sidecar is not None  # save_ros_map writes one by default (sidecar=True)
    return ros


def _report(args, method, inp: _Input, grid: Grid, probs, observed, details, times, ros, snapshots, settings) -> dict:
    """What ``report.json`` holds."""
    report = {
        "ogm_ppl_version": _version(),
        "input": {"path": str(inp.path), "kind": inp.kind, "size_bytes": _size(inp.path)},
        "counts": _counts(inp),
        "grid": {
            "rows": grid.rows,
            "cols": grid.cols,
            "cells": grid.num_cells,
            "resolution_m": grid.resolution,
            "origin_m": list(grid.origin),
            "extent_m": list(grid.extent),
            "observed_cells": int(observed.sum()),
        },
        "method": {"name": method.name, "description": method.doc, **_jsonable(details)},
        "times_s": {
            "read": times["read_s"],
            "ray_cast": times["ray_cast_s"],
            "map": times["map_s"],
            "write": times["write_s"],
        },
        "files": [
            "map.npz",
            "map.png",
            str(Path("ros") / ros.yaml.name),
            str(Path("ros") / ros.image.name),
            str(Path("ros") / ros.sidecar.name),
            "report.json",
            "report.md",
        ]
        + (["snapshots.npz"] if snapshots else []),
        "scores_vs_truth": _scores(probs, observed, inp, grid),
        "settings": settings,
    }
    if inp.log is not None and args.lenient:
        report["bad_lines"] = [{"line": n, "reason": r} for n, r in inp.log.bad_lines[:1000]]
    if inp.bag is not None:
        report["bag"] = {"storage": inp.bag.storage, "scan_topic": inp.bag.scan_topic, "poses": inp.bag.pose_source}
        if args.lenient:
            report["bad_messages"] = [
                {"topic": t, "message": i, "reason": r} for t, i, r in inp.bag.bad_messages[:1000]
            ]
    return report


def run(args) -> int:
    """``ogm-ppl map``: print one line on success."""
    r = cmd_map(args)
    t = r["times_s"]
    print(
        f"ogm-ppl map: {r['grid']['cols']} x {r['grid']['rows']} cells, "
        f"{_plural(r['counts']['scans'], 'scan')}, method {args.method}; read {_fmt_s(t['read'])}, "
        f"map {_fmt_s(t['map'])} -> {args.out}"
    )
    return 0
