r"""Every shipped CARMEN log through the ``ogm-ppl map`` command, with its times and sizes.

The Intel log as in thesis Section 6.2 (5 cm cells, full extent, the ``p21`` update term, readings at or beyond
20 m dropped) and the logs of ``carmen/`` in the shared data folder (5 cm, full extent, ``p21``, every reading
kept), each through the command-line entry point (:func:`ogm_ppl.cli.main`) with nothing but arguments: the
study measures what a user of the command gets. :func:`map_all_logs` writes ``<out>/<name>/`` (the files of
``ogm-ppl map``) and ``<out>/summary.md`` (one row per log: scans, beams, beams dropped, grid, the times of
reading, mapping and writing, the command's wall time and the files' sizes).
"""

from __future__ import annotations

import json
import time
from collections.abc import Sequence
from pathlib import Path

__all__ = ["COMMON", "log_jobs", "map_all_logs"]

#: the options of every log's ``ogm-ppl map``
COMMON = ["--resolution", "0.05", "--auto-extent", "--method", "p21"]
#: the Intel log, under the shared data folder
INTEL = "intel-lab/intel-corrected.log.gz"


def log_jobs(data: str | Path) -> dict[str, list[str]]:
    """Log name -> ``ogm-ppl map`` arguments (without ``--out``) of the logs under the shared data folder
    ``data``: ``intel`` (readings at 20 m or beyond dropped) and each ``carmen/*.log.gz``."""
    data = Path(data)
    out = {"intel": [str(data / INTEL), *COMMON, "--max-usable-range", "20"]}
    for log in sorted((data / "carmen").glob("*.log.gz")):
        out[log.name.removesuffix(".log.gz").removesuffix("-corrected")] = [str(log), *COMMON]
    return out


def _mb(path: Path) -> str:
    return f"{path.stat().st_size / 1e6:.1f}"


def map_all_logs(out: str | Path, data: str | Path, only: Sequence[str] | None = None) -> tuple[str, list[str]]:
    """Map each log of :func:`log_jobs` (``only``: these names) into ``out/<name>`` and write ``out/summary.md``.

    Returns ``(the summary's Markdown, the names of the logs whose command failed)``; a failed log gets a row
    that says so.
    """
    from ogm_ppl.cli import main as ogm_ppl
    from ogm_ppl.io import atomic_write_text

    out = Path(out)
    todo = log_jobs(data)
    if only:
        todo = {k: v for k, v in todo.items() if k in only}
    rows, failed = [], []
    t_all = time.perf_counter()
    for name, cli_args in todo.items():
        folder = out / name
        t0 = time.perf_counter()
        rc = ogm_ppl(["map", *cli_args, "--out", str(folder)])
        wall = time.perf_counter() - t0
        if rc != 0:
            failed.append(name)
            rows.append(f"| {name} | failed (exit {rc}) |" + " |" * 11)
            continue
        r = json.loads((folder / "report.json").read_text())
        c, g, t = r["counts"], r["grid"], r["times_s"]
        rows.append(
            f"| {name} | {c['scans']:,} | {c['beams']:,} | {c['dropped_beams']:,} | {g['cols']} x {g['rows']} "
            f"| {g['cells'] / 1e6:.2f} | {t['read']:.2f} | {t['map']:.2f} | {t['write']:.2f} | {wall:.1f} "
            f"| {_mb(folder / 'map.npz')} | {_mb(folder / 'map.png')} | {_mb(folder / 'ros' / 'map.pgm')} |"
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
    text = "\n".join(lines)
    atomic_write_text(out / "summary.md", text)
    return text, failed
