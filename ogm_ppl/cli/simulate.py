"""``ogm-ppl simulate --map KIND|PNG --out FILE.npz``: a stop-and-scan dataset (thesis Section 6.1) on a
generated ground truth or a PNG floor plan."""

from __future__ import annotations

import time
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ogm_ppl.datasets.mapgen import KINDS
from ogm_ppl.grid import Grid

if TYPE_CHECKING:
    pass
from ogm_ppl.cli._common import (
    CLIError,
    _jsonable,
    _nonneg_float,
    _number,
    _pos_float,
    _pos_int,
    _prepare_out_file,
    _refuse_out_over_inputs,
    _seed,
    _steps,
    _version,
)
from ogm_ppl.inputs import check_readable


def add_parser(sub) -> None:
    """The ``simulate`` subcommand's options."""
    s = sub.add_parser(
        "simulate",
        help="a simulated stop-and-scan dataset (Section 6.1)",
        description="Simulate a stop-and-scan dataset (360 degree scans at the stops of a "
        "frontier-exploration route) on a ground-truth map and save it as a "
        "dataset file with the truth.",
    )
    s.add_argument(
        "--map",
        nargs="+",
        required=True,
        metavar="SPEC",
        help="ground truth: 'generated KIND' (or just KIND, or generated:KIND), KIND one of "
        f"{', '.join(KINDS)}; or a PNG floor plan (dark pixels < 128 are occupied)",
    )
    s.add_argument("--out", type=Path, required=True, metavar="FILE.npz", help="dataset file to write")
    s.add_argument(
        "--size",
        type=_number(int, 60),
        default=500,
        metavar="N",
        help="generated map of N x N cells (default 500 as in Fig. 5.9; at least 60; outer wall "
        "min(20, N // 4) cells thick)",
    )
    s.add_argument("--resolution", type=_pos_float, default=0.05, metavar="M", help="metres per cell (default 0.05)")
    s.add_argument(
        "--poses",
        type=_pos_int,
        metavar="N",
        help="at most N stops (default: explore until 95 %% of the free space is seen)",
    )
    s.add_argument("--beams", type=_pos_int, default=720, metavar="B", help="beams per 360 degree scan (default 720)")
    s.add_argument(
        "--max-range-cells",
        type=_pos_float,
        default=75.0,
        metavar="F",
        help="sensor maximum range in cells (default 75)",
    )
    s.add_argument(
        "--sigma", type=_nonneg_float, default=3.0, metavar="CELLS", help="Gaussian range noise in cells (default 3)"
    )
    s.add_argument("--seed", type=_seed, default=0, metavar="S", help="random seed (0 to 2^62, default 0)")


def _truth_from_spec(spec: list[str], size: int, seed: int) -> tuple[np.ndarray, dict]:
    from ogm_ppl.datasets.mapgen import generate_map

    words = spec[1:] if spec[0] == "generated" else spec
    if len(words) == 1 and words[0].startswith("generated:"):
        words = [words[0][len("generated:") :]]
    if len(words) == 1 and words[0] in KINDS:
        border = min(20, size // 4)  # Fig. 5.9's 20-cell outer wall, thinner on small maps
        truth = generate_map(words[0], (size, size), seed=seed, border=border)
        return truth, {"map": "generated", "kind": words[0], "size": size, "border": border}
    if len(words) == 1 and spec[0] != "generated" and (words[0].lower().endswith(".png") or Path(words[0]).exists()):
        path = Path(words[0])
        check_readable(path)
        from PIL import Image, UnidentifiedImageError

        try:
            with Image.open(path) as im:
                grey = np.asarray(im.convert("L"))
        except (UnidentifiedImageError, OSError) as e:
            raise CLIError(f"{path}: not a readable image ({e})") from None
        occ = grey < 128
        occ[[0, -1], :] = occ[:, [0, -1]] = True  # a closed outer wall: beams end inside the map
        if occ.all():
            raise CLIError(
                f"argument --map: {path} has no free cell: each of its {occ.shape[1]} x {occ.shape[0]} pixels is "
                "darker than 128 (occupied) or on the one-pixel outer wall the simulation adds; a floor plan needs "
                "light (>= 128) free space for the robot"
            )
        return occ[::-1].copy(), {"map": "png", "path": str(path)}  # image row 0 is the top (largest y)
    raise CLIError(
        f"argument --map: expected 'generated KIND' with KIND one of {', '.join(KINDS)}, "
        f"or a PNG file; got {' '.join(spec)!r}"
    )


def _source_name(source: dict) -> str:
    """The ground truth as ``--map`` gave it: the PNG's path or ``generated KIND``."""
    return source["path"] if source["map"] == "png" else f"generated {source['kind']}"


def cmd_simulate(args) -> dict:
    """``ogm-ppl simulate``: stop-and-scan dataset on a generated map or PNG, saved with its truth."""
    from ogm_ppl.datasets import save_dataset
    from ogm_ppl.datasets.stop_and_scan import stop_and_scan

    _refuse_out_over_inputs(args.out, [Path(w) for w in args.map if Path(w).exists()])  # a PNG plan
    _prepare_out_file(args.out)
    with _steps(3, "ogm-ppl simulate") as bar:
        bar.set_postfix_str("ground truth")
        truth, source = _truth_from_spec(args.map, args.size, args.seed)
        grid = Grid(truth.shape, args.resolution)
        bar.update()
        bar.set_postfix_str("route and scans")
        t0 = time.perf_counter()
        try:
            data = stop_and_scan(
                truth,
                grid,
                num_poses=args.poses,
                beams=args.beams,
                max_range_cells=args.max_range_cells,
                sigma_cells=args.sigma,
                seed=args.seed,
            )
        except ValueError as e:
            if str(e).startswith(("truth ", "no free cell")):  # the ground truth's fault: name where it came from
                raise CLIError(f"argument --map: {_source_name(source)}: {e}") from None
            raise
        seconds = time.perf_counter() - t0
        bar.update()
        bar.set_postfix_str("writing")
        settings = dict(data.settings, **source, resolution=args.resolution, generator="stop_and_scan")
        save_dataset(
            args.out,
            data.scans,
            grid=grid,
            truth=data.truth,
            settings=_jsonable(settings),
            provenance={"tool": "ogm-ppl simulate", "ogm_ppl_version": _version()},
        )
        bar.update()
    return {
        "poses": data.scans.num_scans,
        "beams": data.scans.beams_per_scan,
        "grid": list(grid.shape),
        "seconds": seconds,
    }


def run(args) -> int:
    """``ogm-ppl simulate``: print one line on success."""
    r = cmd_simulate(args)
    print(
        f"ogm-ppl simulate: {r['poses']} poses x {r['beams']} beams on {r['grid'][1]} x {r['grid'][0]} "
        f"cells -> {args.out}"
    )
    return 0
