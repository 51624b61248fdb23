"""Map every shipped CARMEN log with the ``ogm-ppl map`` command and summarise times and sizes.

The Intel log as in thesis Section 6.2 (5 cm cells, full extent, the p21 update term, readings at or beyond
20 m dropped) and the nine logs of ``/work/shared/data/carmen`` (5 cm, full extent, p21, every reading
kept), each through the command-line entry point (``ogm_ppl.cli.main``) with nothing but arguments.
Writes ``out/logs/<name>/`` (the files of ``ogm-ppl map``) and ``out/logs/summary.md``.

    python experiments/map_all_logs.py [--out out/logs] [--only intel,seattle]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from ogm_ppl.cli import main as ogm_ppl
from ogm_ppl.io import atomic_write_text

DATA = Path(__file__).resolve().parents[2] / "shared" / "data"  # shared/ beside the repository
INTEL = DATA / "intel-lab" / "intel-corrected.log.gz"
COMMON = ["--resolution", "0.05", "--auto-extent", "--method", "p21"]


def jobs() -> dict[str, list[str]]:
    """Log name -> ``ogm-ppl map`` arguments (without ``--out``)."""
    out = {"intel": [str(INTEL), *COMMON, "--max-usable-range", "20"]}
    for log in sorted((DATA / "carmen").glob("*.log.gz")):
        out[log.name.removesuffix(".log.gz").removesuffix("-corrected")] = [str(log), *COMMON]
    return out


def _mb(path: Path) -> str:
    return f"{path.stat().st_size / 1e6:.1f}"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=Path("out/logs"), help="output directory (default out/logs)")
    ap.add_argument("--only", help="comma-separated log names to map (default: all)")
    args = ap.parse_args(argv)
    todo = jobs()
    if args.only:
        todo = {k: v for k, v in todo.items() if k in args.only.split(",")}
    rows, failed = [], []
    t_all = time.perf_counter()
    for name, cli_args in todo.items():
        out = args.out / name
        cmd = ["map", *cli_args, "--out", str(out)]
        print("ogm-ppl " + " ".join(cmd), flush=True)
        t0 = time.perf_counter()
        rc = ogm_ppl(cmd)
        wall = time.perf_counter() - t0
        if rc != 0:
            failed.append(name)
            rows.append(f"| {name} | failed (exit {rc}) |" + " |" * 11)
            continue
        r = json.loads((out / "report.json").read_text())
        c, g, t = r["counts"], r["grid"], r["times_s"]
        rows.append(
            f"| {name} | {c['scans']:,} | {c['beams']:,} | {c['dropped_beams']:,} | {g['cols']} x {g['rows']} "
            f"| {g['cells'] / 1e6:.2f} | {t['read']:.2f} | {t['map']:.2f} | {t['write']:.2f} | {wall:.1f} "
            f"| {_mb(out / 'map.npz')} | {_mb(out / 'map.png')} | {_mb(out / 'ros' / 'map.pgm')} |"
        )
    lines = [
        "# ogm-ppl map on every shipped CARMEN log",
        "",
        "Each row is one `ogm-ppl map LOG --resolution 0.05 --auto-extent --method p21 --out out/logs/<name>` "
        "(Intel adds `--max-usable-range 20`, the protocol of thesis Section 6.2). Times in seconds: `read` "
        "the CARMEN reader, `map` the fused ray cast + log-odds update, `write` map.npz + map.png + ROS map; "
        "`wall` the whole command in-process. Sizes in MB.",
        "",
        "| log | scans | beams | dropped | grid (W x H) | Mcells | read s | map s | write s | wall s "
        "| map.npz | map.png | ros/map.pgm |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|",
        *rows,
        "",
        f"Total {time.perf_counter() - t_all:.1f} s on {len(todo)} logs"
        + (f"; failed: {', '.join(failed)}" if failed else "")
        + ".",
        "",
    ]
    atomic_write_text(args.out / "summary.md", "\n".join(lines))
    print("\n".join(lines))
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
