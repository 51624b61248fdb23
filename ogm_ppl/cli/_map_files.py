"""What ``ogm-ppl map`` writes and reads back: ``map.npz`` (:func:`load_map`), ``map.png`` and the
report's Markdown."""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ogm_ppl.grid import Grid
from ogm_ppl.io import atomic_write

if TYPE_CHECKING:
    pass
from ogm_ppl.cli._common import (
    _fmt_s,
)

_PNG_UNKNOWN = (217, 217, 217)  # the light grey of viz.plot_map for unknown cells
MAP_FORMAT = "ogm_ppl.map"
MAP_FORMAT_VERSION = 1


def _atomic_savez(path: Path, **arrays) -> None:
    with atomic_write(path) as f:
        np.savez_compressed(f, **arrays)


def save_map_png(path: Path, probabilities: np.ndarray, observed: np.ndarray, grid: Grid) -> None:
    """One pixel per cell on the thesis colour scale (:func:`ogm_ppl.viz.thesis_cmap`), unknown cells
    grey, north (largest y) up. Uses a 256-entry lookup table, so large maps cost 3 bytes a cell."""
    from PIL import Image

    from ogm_ppl.viz import thesis_cmap

    lut = np.round(thesis_cmap()(np.linspace(0.0, 1.0, 256))[:, :3] * 255).astype(np.uint8)
    p = np.nan_to_num(np.asarray(probabilities, dtype=np.float64).reshape(grid.shape), nan=0.5)
    idx = np.clip(np.rint(p * 255), 0, 255).astype(np.uint8)
    rgb = lut[idx]
    rgb[~np.asarray(observed, bool).reshape(grid.shape)] = _PNG_UNKNOWN
    img = Image.fromarray(np.ascontiguousarray(rgb[::-1]), "RGB")
    with atomic_write(path) as f:
        img.save(f, "PNG", compress_level=3)


def load_map(path: str | os.PathLike) -> dict:
    """Read a ``map.npz`` written by ``ogm-ppl map``: probabilities / observed (grid-shaped), grid, settings."""
    with np.load(path, allow_pickle=False) as z:
        if str(z["format"]) != MAP_FORMAT:
            raise ValueError(f"{path}: not an {MAP_FORMAT} file")
        g = z["grid"]
        grid = Grid((int(g[0]), int(g[1])), float(g[2]), (float(g[3]), float(g[4])))
        return {
            "probabilities": z["probabilities"],
            "observed": z["observed"],
            "grid": grid,
            "method": str(z["method"]),
            "settings": json.loads(str(z["settings"])),
        }


def _report_md(r: dict) -> str:
    c, g, t, m = r["counts"], r["grid"], r["times_s"], r["method"]
    of = f" ({'; '.join(c['selection'])})" if "selection" in c else ""
    over = " (over all the scans read)" if "selection" in c else ""
    lines = [
        f"# ogm-ppl map: {Path(r['input']['path']).name}",
        "",
        f"- input: `{r['input']['path']}` ({r['input']['kind']}, {r['input']['size_bytes']:,} bytes)",
        f"- scans: {c['scans']:,}{of}; beams: {c['beams']:,}; valid: {c['valid_beams']:,}; dropped: "
        f"{c['dropped_beams']:,}; max-range readings: {c['max_range_readings']:,}",
    ]
    if "no_return" in c:
        bad = f"bad lines: {c['bad_lines']}" if "bad_lines" in c else f"bad messages: {c['bad_messages']}"
        lines.append(
            f"- dropped by rule: no return {c['no_return']:,}, beyond usable range "
            f"{c['beyond_usable']:,}, below min range {c['below_min']:,}{over}; {bad}"
        )
    if "no_pose" in c:
        b = r["bag"]
        lines.append(
            f"- bag ({b['storage']}): {c['scans_read']:,} scans on {b['scan_topic']}, {c['no_pose']:,} dropped "
            f"without a pose; poses from {b['poses']} ({c['pose_samples']:,} samples)"
        )
    lines += [
        f"- grid: {g['cols']} x {g['rows']} cells ({g['cells']:,}) at {g['resolution_m']} m, origin "
        f"({g['origin_m'][0]:.3f}, {g['origin_m'][1]:.3f}); observed cells: {g['observed_cells']:,}",
        f"- method: {m['name']} ({m['description']})"
        + "".join(f"; {k} = {v}" for k, v in m.items() if k not in ("name", "description")),
        f"- times: read {_fmt_s(t['read'])}, ray cast {_fmt_s(t['ray_cast'])}, map {_fmt_s(t['map'])}, "
        f"write {_fmt_s(t['write'])}",
    ]
    if r.get("scores_vs_truth"):
        sc = r["scores_vs_truth"]
        lines.append(
            f"- against the truth ({sc['mask']}): best F1 {sc['best_f1']:.3f} at "
            f"{sc['best_threshold']:.2f}, ROC AUC {sc['roc_auc']:.3f}"
        )
    lines += ["", "Files: " + ", ".join(f"`{f}`" for f in r["files"]) + "."]
    if r.get("bad_messages"):
        lines += ["", "## Skipped messages (--lenient)", ""]
        lines += [f"- {b['topic'] or 'storage'} message {b['message']}: {b['reason']}" for b in r["bad_messages"][:50]]
    if r.get("bad_lines"):
        lines += ["", "## Skipped lines (--lenient)", ""]
        lines += [f"- line {b['line']}: {b['reason']}" for b in r["bad_lines"][:50]]
        if len(r["bad_lines"]) > 50:
            lines.append(f"- ... {len(r['bad_lines']) - 50} more in report.json")
    return "\n".join(lines) + "\n"
