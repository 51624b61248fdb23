"""``ogm-ppl convert LOG|BAG --out FILE.npz``: a CARMEN log or a ROS bag as a dataset file."""

from __future__ import annotations

import time
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    pass
from ogm_ppl.cli._common import (
    _jsonable,
    _pos_float,
    _prepare_out_file,
    _version,
)
from ogm_ppl.cli._input import (
    _add_bag_options,
    _add_reader_options,
    _bag_kwargs,
    _check_input,
    _is_bag,
    _reader_kwargs,
    _refuse_bag_flags,
)


def add_parser(sub) -> None:
    """The ``convert`` subcommand's options."""
    c = sub.add_parser(
        "convert",
        help="a CARMEN log or a ROS bag as a dataset file",
        description="Read a CARMEN log (plain or gzip) or a ROS bag and save its scans as a dataset file.",
    )
    c.add_argument("log", type=Path, metavar="LOG|BAG", help="the CARMEN log or ROS bag")
    c.add_argument("--out", type=Path, required=True, metavar="FILE.npz", help="dataset file to write")
    c.add_argument(
        "--resolution",
        type=_pos_float,
        metavar="M",
        help="also store a grid of this resolution covering the log (extent + 1 m margin)",
    )
    _add_reader_options(c, carmen_only=False)
    _add_bag_options(c)


def cmd_convert(args) -> dict:
    """``ogm-ppl convert``: CARMEN log or ROS bag -> dataset file."""
    from ogm_ppl.datasets import read_bag, read_carmen, save_dataset

    if _is_bag(args.log):
        kw = _bag_kwargs(args, args.log)
        _prepare_out_file(args.out)
        t0 = time.perf_counter()
        bag = read_bag(args.log, **kw)
        seconds = time.perf_counter() - t0
        grid = bag.grid(args.resolution) if args.resolution else None
        provenance = {
            "tool": "ogm-ppl convert",
            "source": str(args.log),
            "reader": "ogm_ppl.datasets.read_bag",
            "ogm_ppl_version": _version(),
            "storage": bag.storage,
            "bad_messages": len(bag.bad_messages),
            "counts": bag.counts,
        }
        save_dataset(args.out, bag.scans, grid=grid, settings=_jsonable(bag.settings), provenance=_jsonable(provenance))
        return {
            "scans": bag.scans.num_scans,
            "beams": bag.scans.beams_per_scan,
            "bad_lines": len(bag.bad_messages),
            "what": "bad messages",
            "seconds": seconds,
        }
    _refuse_bag_flags(args, args.log)
    _check_input(args.log)
    _prepare_out_file(args.out)
    t0 = time.perf_counter()
    log = read_carmen(args.log, **_reader_kwargs(args))
    seconds = time.perf_counter() - t0
    grid = log.grid(args.resolution) if args.resolution else None
    provenance = {
        "tool": "ogm-ppl convert",
        "source": str(args.log),
        "reader": "ogm_ppl.datasets.read_carmen",
        "ogm_ppl_version": _version(),
        "num_lines": log.num_lines,
        "bad_lines": len(log.bad_lines),
        "counts": log.counts,
    }
    save_dataset(args.out, log.scans, grid=grid, settings=_jsonable(log.settings), provenance=_jsonable(provenance))
    return {
        "scans": log.scans.num_scans,
        "beams": log.scans.beams_per_scan,
        "bad_lines": len(log.bad_lines),
        "what": "bad lines",
        "seconds": seconds,
    }


def run(args) -> int:
    """``ogm-ppl convert``: print one line on success."""
    r = cmd_convert(args)
    print(
        f"ogm-ppl convert: {r['scans']} scans x {r['beams']} beams ({r['bad_lines']} {r['what']} skipped) -> {args.out}"
    )
    return 0
