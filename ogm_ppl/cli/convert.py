"""``ogm-ppl convert LOG|BAG --out FILE.npz``: a CARMEN log or a ROS bag as a dataset file."""

from __future__ import annotations

import time
from pathlib import Path

from ogm_ppl.cli._common import (
    _jsonable,
    _pos_float,
    _prepare_out_file,
    _version,
)
from ogm_ppl.cli._input import (
    _add_bag_options,
    _add_reader_options,
    _input_values,
    _parse_options,
)

#: the function each shipped kind that reads a file is read with, named in the dataset file's provenance
_READERS = {
    "log": "ogm_ppl.datasets.read_carmen",
    "bag": "ogm_ppl.datasets.read_bag",
    "npz": "ogm_ppl.datasets.load_dataset",
}


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
    """``ogm-ppl convert``: a CARMEN log, a ROS bag (or any input a kind reads) -> dataset file."""
    from ogm_ppl.datasets import save_dataset
    from ogm_ppl.inputs import read_input

    kind, values = _input_values(args, args.log)
    options = _parse_options(kind, values, args.log)
    _prepare_out_file(args.out)
    t0 = time.perf_counter()
    data = read_input(kind.name, args.log, options)
    seconds = time.perf_counter() - t0
    grid = data.covering_grid(args.resolution) if args.resolution else None
    rec = data.record
    bad = getattr(rec, "bad_messages", None)
    what, bad = ("bad messages", bad) if bad is not None else ("bad lines", getattr(rec, "bad_lines", []))
    provenance: dict = {
        "tool": "ogm-ppl convert",
        "source": str(args.log),
        "reader": _READERS.get(kind.name, f"ogm_ppl.inputs kind {kind.name!r}"),
        "ogm_ppl_version": _version(),
    }
    for k in ("storage", "num_lines"):
        if hasattr(rec, k):
            provenance[k] = getattr(rec, k)
    provenance[what.replace(" ", "_")] = len(bad)
    if hasattr(rec, "counts"):
        provenance["counts"] = rec.counts
    save_dataset(args.out, data.scans, grid=grid, settings=_jsonable(data.settings), provenance=_jsonable(provenance))
    return {
        "scans": data.scans.num_scans,
        "beams": data.scans.beams_per_scan,
        "bad_lines": len(bad),
        "what": what,
        "seconds": seconds,
    }


def run(args) -> int:
    """``ogm-ppl convert``: print one line on success."""
    r = cmd_convert(args)
    print(
        f"ogm-ppl convert: {r['scans']} scans x {r['beams']} beams ({r['bad_lines']} {r['what']} skipped) -> {args.out}"
    )
    return 0
