"""The results and benchmark tables of the docs and the README, generated from committed JSON snapshots.

Every table shown in ``docs/`` or in the README's ``<!-- generated: NAME -->`` block is built here from a
JSON snapshot in ``docs/results/`` (a copy of what a benchmark or experiment wrote), never typed by hand.
Each snapshot carries a ``"provenance"`` block (command line, git commit, machine, date): the benchmarks
stamp their own JSON (``benchmarks/_common.py``: ``write_json``); for an experiment's JSON the
``snapshot`` command below adds the stamp when copying it. Under each table the command, commit and
machine are printed, so a reader can rerun it and a rerun updates the page.

Commands (from the repository root)::

    python tools/gen_docs_tables.py snapshot out/bench/bench_ogm.json          # copy a stamped JSON
    python tools/gen_docs_tables.py snapshot out/report.json --name headline --command "make run"
    python tools/gen_docs_tables.py merge out/experiments/x/metrics.json --into NAME --command "..."
    python tools/gen_docs_tables.py readme           # rewrite the README's generated blocks
    python tools/gen_docs_tables.py readme --check   # exit 1 if they differ from the snapshots
    python tools/gen_docs_tables.py show NAME        # one table as Markdown
    python tools/gen_docs_tables.py list             # every table's name and its snapshot's

``--results DIR`` reads and writes the snapshots of another folder (``readme --readme PATH``: another README).

The Sphinx extension ``docs/_ext/ogm_tables.py`` renders the same :class:`Table` objects into the pages
(``{ogm-table} NAME``); ``tests/test_docs.py`` runs these commands (``readme --check``, ``list``, ``show``, and
``snapshot`` and ``merge`` into a folder of its own).
"""

from __future__ import annotations

import argparse
import datetime
import json
import math
import re
import sys
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
RESULTS = ROOT / "docs" / "results"
README = ROOT / "README.md"

__all__ = [
    "RESULTS",
    "TABLES",
    "Table",
    "load_snapshot",
    "merge",
    "provenance_line",
    "readme_block",
    "snapshot",
    "table",
    "to_markdown",
    "update_readme",
]


@dataclass(frozen=True)
class Table:
    """One generated table: a caption, a header row, body rows (strings) and where the numbers came from."""

    caption: str
    header: list[str]
    rows: list[list[str]]
    provenance: dict
    note: str = ""


# ------------------------------------------------------------------------------------------ snapshots
_PROVENANCE_KEYS = ("command", "commit", "machine", "date")


def load_snapshot(name: str, results: Path = RESULTS) -> dict:
    """``docs/results/NAME.json``, validated: a JSON object with a complete ``"provenance"`` block."""
    path = results / f"{name}.json"
    doc = json.loads(path.read_text())
    if not isinstance(doc, dict):
        raise ValueError(f"{path}: a snapshot is a JSON object")
    prov = doc.get("provenance")
    missing = [k for k in _PROVENANCE_KEYS if not isinstance(prov, dict) or k not in prov]
    if missing:
        raise ValueError(f"{path}: provenance lacks {', '.join(missing)}")
    return doc


def drop_dataset_curves(doc: dict) -> int:
    """Remove the per-dataset precision-recall curves (``scores[i][block]["curve"]``) of an experiment's
    summary in place, keeping each dataset's scores and the pooled curves; returns how many were removed."""
    n = 0
    for row in doc.get("scores") or ():
        for block in row.values() if isinstance(row, dict) else ():
            if isinstance(block, dict) and block.pop("curve", None) is not None:
                n += 1
    return n


def _stamped(src: Path, command: str | None, drop_curves: bool) -> dict:
    """The JSON ``src`` with its provenance (:func:`snapshot`'s rules), the curves left out if asked."""
    doc = json.loads(Path(src).read_text())
    if not isinstance(doc, dict):
        raise ValueError(f"{src}: expected a JSON object")
    if "provenance" not in doc:
        if not command:
            raise ValueError(f"{src} has no provenance: pass the command that produced it (--command)")
        sys.path.insert(0, str(ROOT / "benchmarks"))
        from _common import provenance

        prov = provenance(command)
        mtime = datetime.datetime.fromtimestamp(Path(src).stat().st_mtime, datetime.timezone.utc)
        prov["date"] = mtime.strftime("%Y-%m-%dT%H:%M:%SZ")
        doc = {"provenance": prov, **doc}
    elif command:
        raise ValueError(f"{src} is already stamped (command {doc['provenance'].get('command')!r})")
    if drop_curves and drop_dataset_curves(doc):
        doc["provenance"]["dropped"] = "the per-dataset precision-recall curves (scores[*][block].curve)"
    return doc


def snapshot(
    src: Path,
    name: str | None = None,
    command: str | None = None,
    results: Path = RESULTS,
    drop_curves: bool = False,
) -> Path:
    """Copy the JSON ``src`` into ``results/NAME.json`` (``NAME`` defaults to the file's stem).

    A JSON without a ``"provenance"`` block (an experiment's own output) gets one: ``command`` (required
    then), the commit of this checkout and this machine, dated by ``src``'s modification time, so take the
    snapshot right after the run, from the checkout that ran it. ``drop_curves``: leave out the per-dataset
    precision-recall curves (:func:`drop_dataset_curves`; no table reads them), and say so in the
    provenance (``"dropped"``); a stamped snapshot keeps its provenance otherwise.
    """
    from ogm_ppl.io import atomic_write_text

    doc = _stamped(src, command, drop_curves)
    return atomic_write_text(results / f"{name or Path(src).stem}.json", json.dumps(doc, indent=1, allow_nan=True))


def _is_error_split(doc: dict) -> bool:
    """Whether ``doc`` is ``ogm-ppl study table_6_4_errors``'s output (algorithms keyed by name)."""
    return isinstance(doc.get("algorithms"), dict) and "oracles" in doc


def _is_active(doc: dict) -> bool:
    """Whether ``doc`` is an ``active`` (exploration) experiment's ``metrics.json`` (runs keyed by rule)."""
    return doc.get("format") == "ogm_ppl.experiment.active"


def _algorithms(doc: dict) -> set[str]:
    if _is_error_split(doc):
        return set(doc["algorithms"])
    if _is_active(doc):
        return {r["method"] for r in doc.get("runs") or ()}
    return {row["algorithm"] for key in ("scores", "pooled", "runs") for row in doc.get(key) or ()}


def _same_data(doc: dict) -> dict:
    """What two parts of one merged snapshot must share: the experiment, its seed and datasets (each
    dataset's figures but its seconds), or for an error split the cell counts and the oracles' scores."""
    if _is_error_split(doc):
        return {k: doc.get(k) for k in ("datasets", "cells", "occupied", "oracles")}
    same = {k: doc.get(k) for k in ("format", "format_version", "experiment", "seed")}
    if _is_active(doc):  # the same plans, and every (plan, seed) started from the same cell
        same["plans"] = doc.get("plans")
        starts: dict = {}
        for r in doc.get("runs") or ():
            starts.setdefault((r["plan_id"], r["seed"]), set()).add(str(r["start"]))
        same["starts"] = starts
        return same
    same["datasets"] = [{k: v for k, v in d.items() if k != "seconds"} for d in doc.get("datasets") or ()]
    return same


def _count(x: list | int) -> int:
    return len(x) if isinstance(x, list) else int(x)


def merge(src: Path, into: str, command: str, results: Path = RESULTS, drop_curves: bool = False) -> Path:
    """Add the algorithms of a later run's result ``src`` (an experiment's summary run into another folder,
    ``ogm-ppl study table_6_4_errors``'s split of it, or an ``active`` experiment's ``metrics.json``) to the
    snapshot ``results/INTO.json`` of the same experiment.

    Refused unless both are of the same kind, experiment, seed and datasets (every dataset's figures equal
    but its seconds: the same simulated data; for an error split, the same cell counts and oracle scores;
    for an exploration, the same plans and the same start of every (plan, seed) both ran) and share no
    algorithm, so every row of the result is one run's, scored on the same datasets; pooled rows are per
    algorithm, so they carry over unchanged. An exploration's summary is recomputed from the joined runs
    (:func:`ogm_ppl.experiment.active.summarise`; rules in the snapshot's order, then the new run's, so its
    ratios stay against the snapshot's first rule). The result's provenance joins the two commands (the
    snapshot's first) and keeps each part's stamp under ``"parts"`` (:func:`provenance_line` prints them);
    its own commit, machine and date are the new run's. ``src`` is stamped as :func:`snapshot` stamps it
    (``command`` required). Nothing is written when refused."""
    from ogm_ppl.io import atomic_write_text

    base = load_snapshot(into, results)
    new = _stamped(src, command, drop_curves)
    where = f"{src} into {results / (into + '.json')}"
    if _is_error_split(base) != _is_error_split(new):
        raise ValueError(f"{where}: not the same kind of result")
    a, b = _same_data(base), _same_data(new)
    for key in a:
        if key == "starts":  # each (plan, seed) both ran started from one and the same cell
            sa, sb = a[key], b[key]
            if any(len(sa[k] | sb[k]) != 1 for k in sa.keys() & sb.keys()):
                raise ValueError(f"{where}: starts differs (another spec, seed or simulator)")
            continue
        if a[key] != b[key]:
            raise ValueError(f"{where}: {key} differs (another spec, seed or simulator)")
    both = sorted(_algorithms(base) & _algorithms(new))
    if both:
        raise ValueError(f"{where}: both hold {', '.join(both)}")
    if not _algorithms(new):
        raise ValueError(f"{where}: no algorithm to add")
    out = dict(base)
    if _is_error_split(base):
        out["algorithms"] = {**base["algorithms"], **new["algorithms"]}
    elif _is_active(base):
        from ogm_ppl.experiment.active import summarise

        # the rules in the order of the snapshot, then the new run's: ratios stay against the snapshot's first
        methods = [r["method"] for r in base["summary"]] + [r["method"] for r in new["summary"]]
        out["runs"] = base["runs"] + new["runs"]
        out["summary"] = summarise(out["runs"], methods)
        out["failed"] = {**(base.get("failed") or {}), **(new.get("failed") or {})}
    else:
        for key in ("scores", "pooled", "runs", "executed", "skipped"):
            x, y = base.get(key) or [], new.get(key) or []
            # task lists are joined (a task both ran is listed by each); a count (older summaries) is added
            out[key] = x + y if isinstance(x, list) and isinstance(y, list) else _count(x) + _count(y)
        out["failed"] = {**(base.get("failed") or {}), **(new.get("failed") or {})}
    out["provenance"] = _join_provenance(base["provenance"], new["provenance"])
    return atomic_write_text(results / f"{into}.json", json.dumps(out, indent=1, allow_nan=True))


def _join_provenance(old_p: dict, new_p: dict) -> dict:
    """The provenance of numbers from two runs: the later run's stamp, both commands (the earlier first) and
    each part's stamp under ``"parts"`` (:func:`provenance_line` prints them)."""
    prov = {k: new_p[k] for k in _PROVENANCE_KEYS}
    prov["command"] = f"{old_p['command']}; then {new_p['command']}"
    prov["parts"] = [*(old_p["parts"] if "parts" in old_p else [old_p]), new_p]
    if "dropped" in old_p or "dropped" in new_p:
        prov["dropped"] = old_p.get("dropped") or new_p.get("dropped")
    return prov


def _stamp(prov: dict) -> str:
    m = prov["machine"]
    machine = (
        f"{m.get('cpu', '?')}, {m.get('cores', '?')} cores, Python {m.get('python', '?')}, "
        f"torch {m.get('torch', '?')}, numba {m.get('numba', '?')}"
    )
    commit = prov["commit"][:12] + ("-dirty" if prov["commit"].endswith("-dirty") else "")
    return f"commit {commit} on {machine}; {prov['date'][:10]}"


def provenance_line(prov: dict) -> str:
    """One line under a table: ``command`` at ``commit`` on the machine, date (for a merged snapshot,
    :func:`merge`, the stamp of each part in turn)."""
    if "parts" in prov:
        return f"`{prov['command']}`, in turn at " + "; then at ".join(_stamp(p) for p in prov["parts"])
    return f"`{prov['command']}` at {_stamp(prov)}"


# ------------------------------------------------------------------------------------------ formatting
def _f(x, digits: int = 3) -> str:
    if x is None or (isinstance(x, float) and math.isnan(x)):
        return "–"
    return f"{x:.{digits}f}"


def _g(x, digits: int = 3) -> str:
    if x is None or (isinstance(x, float) and math.isnan(x)):
        return "–"
    return f"{x:.{digits}g}"


def _rate(x: float) -> str:
    return f"{x / 1e6:.2f} M" if x >= 1e6 else f"{x / 1e3:.0f} k"


# ------------------------------------------------------------------------------------------ the tables
HEADLINE_LABELS = {
    "ogm": "traditional OGM (Hähnel)",
    "p21": "log-odds OGM, p21 fitted for this sensor",
    "border-L9": "Gibbs, border prior learned from HouseExpo, L = 9",
    "guide": "amortised guide learned on HouseExpo + IPA plans, one pass, symmetrised",
}


def _headline_label(name: str, prior: dict | None) -> str:
    if name == "learned-L9" and prior:
        how = ", the thesis's border update" if prior.get("update") == "thesis" else ""
        return f"Gibbs, {prior['name']} prior{how} (chosen on training plans), L = 9"
    return HEADLINE_LABELS.get(name, name)


def _by_condition(pooled: list[dict]) -> tuple[dict[str, list[str]], list[str]]:
    """An experiment's pooled rows as ``best F1 / AUC / touched best F1`` per algorithm (in order of first
    appearance), one entry per condition (``"–"`` where the algorithm did not run), and the column headers
    (each condition's share of the readings)."""
    conds = list(dict.fromkeys(p["condition"] for p in pooled))
    frac = {p["condition"]: p["measurement_fraction"] for p in pooled}
    got = {(p["algorithm"], p["condition"]): p for p in pooled}
    cells = {
        a: [_f1_auc_touched(got.get((a, c))) for c in conds] for a in dict.fromkeys(p["algorithm"] for p in pooled)
    }
    return cells, [f"{100 * frac[c]:.3g} % of the readings" for c in conds]


def _f1_auc_touched(p: dict | None) -> str:
    """One pooled row as ``best F1 / AUC / touched best F1`` on the mask (then `` / seconds per map`` where the
    row holds it); ``"–"`` for a run that did not happen."""
    if p is None:
        return "–"
    t = p.get("touched") or {}
    cell = f"{_f(p['mask'].get('best_f1'))} / {_f(p['mask'].get('auc'))} / {_f(t.get('best_f1'))}"
    if p.get("seconds_per_map") is not None:
        cell += f" / {p['seconds_per_map']:.2g} s"
    return cell


def _headline(doc: dict) -> Table:
    cells, header = _by_condition(doc["intel"]["pooled"])
    timed = any(p.get("seconds_per_map") is not None for p in doc["intel"]["pooled"])
    return Table(
        caption="Intel Lab log at 5 cm, half the beams: best F1 / ROC AUC / best F1 on the touched cells"
        + (
            " / seconds per map (wall time on the machine below, which a rerun elsewhere will not repeat; one"
            " chain, compiling excluded; a method fitted for the sensor fits its term in its first map)"
            if timed
            else ""
        ),
        header=["map", *header],
        rows=[[_headline_label(a, doc["intel"].get("prior")), *row] for a, row in cells.items()],
        provenance=doc["provenance"],
        note=f"run time {doc['intel']['seconds']:.0f} s",
    )


def _simulated(doc: dict) -> Table:
    maps = doc["simple2d"]["maps"]
    rows = [[r["label"], _f(r["best_f1"]), _f(r["roc_auc"]), _g(r["seconds"])] for r in maps.values()]
    return Table(
        caption="Simple 2D example (Fig. 2.8 setting), scored against the ground truth near observed cells",
        header=["map", "best F1", "ROC AUC", "seconds"],
        rows=rows,
        provenance=doc["provenance"],
    )


_OGM_LABELS = {
    "ours (fused)": "ours, fused traversal + update",
    "ours (CSR)": "ours, `raycast` (CSR) + `evidence_grid`",
    "numpy (batched)": "batched numpy DDA (`reference.evidence_grid_numpy`)",
    "python loop": "plain per-ray Python loop (timed on 10 scans, scaled by work)",
    "octomap": "OctoMap (`octomap-python`, one thread)",
}


def _bench_ogm(doc: dict) -> Table:
    rows = [
        [
            _OGM_LABELS.get(k, k),
            _g(sec, 3),
            _rate(doc["rays_per_second"][k]),
            f"{doc['updates_per_second'][k] / 1e6:.1f}",
            f"{doc['speedup_of_fused_over'][k]:.1f}x",
        ]
        for k, sec in doc["seconds"].items()
    ]
    s = doc["scene"]
    return Table(
        caption=(
            f"Traditional OGM, {s['grid'][0]} x {s['grid'][1]} grid at {s['resolution_m'] * 100:g} cm, "
            f"{s['rays']:,} rays, max range {s['max_range_cells']} cells: best of several runs, one core"
            + (f" (ours also on {doc['threads']} threads)" if doc.get("threads", 1) > 1 else "")
        ),
        header=["method", "seconds", "rays/s", "M ray-cell updates/s", "the fused kernel is faster by"],
        rows=rows,
        provenance=doc["provenance"],
        note=f"OctoMap: {doc['octomap_status']}",
    )


def _bench_exact(doc: dict) -> Table:
    rows = [
        [f"brute force, K = {r['K']}", "6", _g(r["seconds"]), _g(r["python_loop_seconds_estimated"])]
        for r in doc["brute_force"]
    ]
    rows += [
        [f"pose-constrained 1D, K = {r['K']:,}", str(r["N"]), _g(r["seconds"]), ""] for r in doc["pose_constrained"]
    ]
    return Table(
        caption="Exact posteriors of 1D problems: seconds per posterior (marginals included)",
        header=["method", "readings", "seconds", "a per-map Python loop, estimated (s)"],
        rows=rows,
        provenance=doc["provenance"],
    )


def _bench_patch(doc: dict) -> Table:
    rows = [[k, _g(v)] for k, v in doc["seconds"].items()]
    return Table(
        caption=(
            f"Patch maps of the same scene ({doc['cells']:,} cells, {doc['rays']:,} rays): seconds of one "
            "call each, the first (numba compilation or cache load included)"
        ),
        header=["method", "seconds"],
        rows=rows,
        provenance=doc["provenance"],
    )


def _bench_table_6_6(doc: dict) -> Table:
    names = {"dd": "patch table (data-driven)", "border": "border"}
    rows = []
    for exp, r in doc["experiments"].items():
        for key, v in r["priors"].items():
            full, reg = v["full"], v["region"]
            rows.append(
                [
                    f"{exp} ({r['poses']} poses, {r['rays']:,} rays)",
                    names.get(key, key),
                    _g(v["thesis_s"], 4),
                    f"{full['s_per_sample']:.3f} ({v['speedup_full']:.0f}x)",
                    f"{reg['s_per_sample']:.3f} ({v['speedup_region']:.0f}x)",
                ]
            )
    return Table(
        caption=(
            f"Table 6.6: seconds per map sample (one sweep of 3 x 3 patches, one thread), Intel Lab at "
            f"{doc['resolution_m'] * 100:g} cm, K = {doc['cells']:,} cells; in brackets the thesis's time over ours"
        ),
        header=[
            "experiment",
            "prior",
            "thesis (s)",
            "ours, full map (s)",
            f"ours, within {doc['near_cells']:g} cells of a mapped cell (s)",
        ],
        rows=rows,
        provenance=doc["provenance"],
        note=f"peak RSS {doc['peak_rss_mib']:.0f} MiB; load average {doc['loadavg_start']} -> {doc['loadavg_end']}",
    )


def _bench_parallel(doc: dict) -> Table:
    """Chromatic sweeps in threads: per configuration and sweep the serial time, 1 and 2 threads, the speed-ups
    against one thread and against the serial kernel, and the scaling model's prediction for 16 cores."""
    rows = []
    for i, (name, c) in enumerate(doc["configs"].items()):
        rng = name.removeprefix("range_").removesuffix("m") + " m"
        serial = c["serial_s_per_sweep"]
        # ru_maxrss is a process-wide peak: comparable for the first configuration only
        rss = f"x{c['peak_rss_threads_mib'] / c['peak_rss_serial_mib']:.3f}" if i == 0 else "–"
        for T, t in c["tiles"].items():
            one, two = t["threads_1_s_per_sweep"], t["threads_2_s_per_sweep"]
            rows.append(
                [
                    f"cell sweep, {rng} rays, T {T} ({100 * t['long_cell_fraction']:.0f} % long cells)",
                    f"{serial:.3f}",
                    f"{one:.3f}",
                    f"{two:.3f}",
                    f"x{one / two:.2f}",
                    f"x{serial / two:.2f}",
                    f"x{t['model_speedup_vs_1_thread']['16']:.2f}",
                    rss,
                ]
            )
        for prior, t in (c.get("patch") or {}).items():
            one, two = t["threads_1_s_per_sweep"], t["threads_2_s_per_sweep"]
            rows.append(
                [
                    f"3 x 3 patch sweep, `{prior}`, {rng} rays, T {t['tile']}",
                    f"{t['serial_s_per_sweep']:.3f}",
                    f"{one:.3f}",
                    f"{two:.3f}",
                    f"x{one / two:.2f}",
                    f"x{t['serial_s_per_sweep'] / two:.2f}",
                    "–",
                    "–",
                ]
            )
    return Table(
        caption=(
            f"Chromatic tile sweeps, Intel Lab at {doc['resolution_m'] * 100:g} cm, Experiment {doc['experiment']}: "
            "seconds a sweep (serial kernel, 1 and 2 threads), speed-ups, the scaling model's 16 cores, and the "
            "peak RSS with threads over the serial one (first configuration)"
        ),
        header=[
            "sweep",
            "serial (s)",
            "1 thread (s)",
            "2 threads (s)",
            "2 / 1 thread",
            "2 threads / serial",
            "model, 16 cores",
            "peak RSS",
        ],
        rows=rows,
        provenance=doc["provenance"],
        note=f"load average {doc['loadavg_start']} -> {doc['loadavg_end']}",
    )


def _table_3_1(doc: dict) -> Table:
    rows = [
        [k, _g(v["mean"], 4), "" if v.get("thesis") is None else _g(v["thesis"], 4)] for k, v in doc["rows"].items()
    ]
    return Table(
        caption=(
            f"Table 3.1: mean summed KL to the exact marginals, {doc['datasets']} datasets, "
            f"K = {doc['cells']} latent cells, Gibbs {doc['gibbs_sweeps']:,} sweeps"
        ),
        header=["algorithm", "ours", "thesis (Table 3.1)"],
        rows=rows,
        provenance=doc["provenance"],
        note=f"run time {doc['seconds']:.0f} s",
    )


def _calibration_rows(doc: dict, mask: str) -> tuple[list[str], list[dict]]:
    summ = [s for s in doc["summary"] if s["mask"] == mask]
    return list(dict.fromkeys(s["test"] for s in summ)), summ


def _calibration(doc: dict) -> Table:
    tests, summ = _calibration_rows(doc, "unseen")
    labels = {
        "ogm": "traditional OGM (p21)",
        "uniform": "independent, lambda = 0.5",
        "independent": "independent, lambda learned",
    }

    def key(s: dict) -> str:
        return "ogm" if s["prior"] == "ogm" else "uniform" if s["train"] == "none" else s["prior"]

    own = {(key(s), s["test"]): s for s in summ if s["train"] in (s["test"], "none")}
    rows = []
    order = ["ogm", "uniform", *doc["settings"]["priors"]]
    keys = sorted(dict.fromkeys(k for k, _ in own), key=lambda k: order.index(k) if k in order else len(order))
    for k in keys:
        cells = []
        for t in tests:
            s = own.get((k, t))
            cells += ["–"] * 3 if s is None else [_f(s["nll_bits"]), _f(s["ece"]), _f(s["auc"])]
        rows.append([labels.get(k, k), *cells])
    settings = doc["settings"]
    return Table(
        caption=(
            f"Unseen cells of held-out maps ({settings['plans']} per corpus, {settings['window']} x "
            f"{settings['window']} cells, {settings['poses']} stops x {settings['beams']} beams): NLL (bits/cell) / "
            f"ECE / ROC AUC, each prior learned on the test corpus, marginals pooled over 3 chains of "
            f"{settings['sweeps']} sweeps"
        ),
        header=["method", *(f"{t} {m}" for t in tests for m in ("NLL", "ECE", "AUC"))],
        rows=rows,
        provenance=doc["provenance"],
        note=f"– : skipped, an update would weigh more than {settings['max_support']} configurations",
    )


TARGET_HEADER = ("method", "NLL", "ECE", "ECE pooled", "Brier", "AUC", "best F1", "IoU", "R-hat < 1.05", "s / map")


def _target_cells(s: dict) -> list[str]:
    """A method's cells under :data:`TARGET_HEADER`, from one calibration summary row."""
    keys = ("nll_bits", "ece", "ece_pooled", "brier", "auc", "best_f1", "iou")
    return [s["prior_name"], *(_f(s.get(k)) for k in keys), _f(s.get("rhat_below"), 2), _f(s["seconds"], 1)]


def _calibration_targets(doc: dict) -> Table:
    """Per test corpus, every method learned on it (and traditional OGM, the uniform prior): the unseen cells'
    NLL, ECE (mean over maps, and pooled over them), Brier, ROC AUC, best F1, occupied-class IoU, the share of
    cells with split R-hat < 1.05 (chains only) and seconds a map."""
    tests, summ = _calibration_rows(doc, "unseen")
    order = ["ogm", "uniform", *doc["settings"]["priors"], "guide"]

    def key(s: dict) -> str:
        return "ogm" if s["prior"] == "ogm" else "uniform" if s["train"] == "none" else s["prior"]

    rows = []
    for t in tests:
        own = [s for s in summ if s["test"] == t and s["train"] in (t, "none")]
        own.sort(key=lambda s: order.index(key(s)) if key(s) in order else len(order))
        for s in own:
            rows.append([t, *_target_cells(s)])
    settings = doc["settings"]
    return Table(
        caption=(
            f"Unseen cells of held-out maps ({settings['plans']} per corpus, {settings['window']} x "
            f"{settings['window']} cells, {settings['poses']} stops x {settings['beams']} beams), means over the maps; "
            f"each prior and guide learned on the test corpus; chains: 3 from different starts, {settings['sweeps']} "
            "sweeps each"
        ),
        header=["test", *TARGET_HEADER],
        rows=rows,
        provenance=doc["provenance"],
        note=(
            "NLL in bits per cell; ECE: mean over maps of each map's ECE; ECE pooled: one reliability diagram of "
            "every map's unseen cells; – : no chain (OGM, guides) or skipped"
        ),
    )


def _calibration_plans(doc: dict) -> Table:
    """``calibration.py --plan-files``: every method on the plan set's unseen cells (no prior was learned on
    those buildings, so every training corpus's priors and every guide are listed), as
    :func:`_calibration_targets` lists a corpus's own."""
    _, summ = _calibration_rows(doc, "unseen")
    rows = [_target_cells(s) for s in summ]
    st = doc["settings"]
    outside = {
        "unknown": "cells the plan does not know are walls to the simulated sensor and are not scored",
        "occupied": "cells the plan does not know count as occupied, as the corpora's exteriors do",
    }[st.get("plan_outside", "occupied")]
    maps = summ[0]["maps"] if summ else 0
    kernel = st.get("kernel", "gibbs")
    sampler = "" if kernel == "gibbs" else f" of the {kernel} sampler"
    if kernel == "guided":
        sampler += f" (blocks proposed by guide:{st['proposal_guide']})"
    return Table(
        caption=(
            f"Unseen cells of {maps} plans of buildings in no training set ({st['plan_set']}; a {st['window']} x "
            f"{st['window']}-cell window of each, {st['poses']} stops x {st['beams']} beams), means over the plans; "
            f"{outside}; chains{sampler}: 3 from different starts, {st['sweeps']} sweeps each"
        ),
        header=list(TARGET_HEADER),
        rows=rows,
        provenance=doc["provenance"],
        note=(
            "KIND:CORPUS: the prior learned on that corpus; guide:C: the guide learned there (@sym: symmetrised); "
            "NLL in bits per cell; ECE: mean over plans of each plan's ECE; ECE pooled: one reliability diagram of "
            "every plan's unseen cells; – : no chain (OGM, guides)"
        ),
    )


def _method_by_test(summ: list[dict], tests: list[str], keep, cell) -> list[list[str]]:
    """One row per method (``prior_name``, in order of first appearance) of the summary rows ``keep`` admits,
    one column per test corpus: ``cell(row)``, or ``"–"`` where the method did not run on it."""
    got = {(s["prior_name"], s["test"]): s for s in summ if keep(s)}
    names = dict.fromkeys(n for n, _ in got)
    return [[n, *("–" if (n, t) not in got else cell(got[n, t]) for t in tests)] for n in names]


def _calibration_cross(doc: dict) -> Table:
    tests, summ = _calibration_rows(doc, "unseen")
    rows = _method_by_test(
        summ,
        tests,
        lambda s: s["prior"] != "ogm",
        lambda s: f"{_f(s['nll_bits'])} / {_f(s['auc'])} / {_f(s['rhat_below'], 2)}",
    )
    # pairs (prior with its training corpus, test corpus) whose NLL exceeds the independent prior's (lambda 0.5)
    ref = {s["test"]: s["nll_bits"] for s in summ if s["prior_name"] == "independent"}
    counts = {}
    for s in summ:
        if s["prior"] == "ogm" or s["prior"].startswith("independent") or s["test"] not in ref:
            continue
        key = "tempered (@)" if "@" in s["prior_name"] else "untempered"
        above, total = counts.get(key, (0, 0))
        counts[key] = (above + (s["nll_bits"] > ref[s["test"]]), total + 1)
    note = "; ".join(f"{k}: {a} of {n} pairs above the independent prior's NLL" for k, (a, n) in counts.items())
    return Table(
        caption=(
            "Across corpora, unseen cells: NLL (bits/cell) / ROC AUC / share of cells with split R-hat < 1.05, "
            "each prior (with its training corpus) on each test corpus"
        ),
        header=["prior", *tests],
        rows=rows,
        provenance=doc["provenance"],
        note=note,
    )


def _calibration_corpora(doc: dict) -> Table:
    """Each prior learned on each corpus, scored on the held-out maps of every test corpus (and on plan files),
    unseen cells: NLL mean with its spread over the maps (min-max), and ROC AUC."""
    tests, summ = _calibration_rows(doc, "unseen")

    def cell(s: dict) -> str:
        sp = s.get("spread", {}).get("nll_bits", {})
        return f"{_f(s['nll_bits'])} ({_f(sp.get('min'))}-{_f(sp.get('max'))}) / {_f(s['auc'])}"

    rows = _method_by_test(summ, tests, lambda s: True, cell)
    st = doc["settings"]
    maps = sorted({s["maps"] for s in summ})
    return Table(
        caption=(
            f"Priors learned on each corpus (rows), on the unseen cells of the held-out maps of each test set "
            f"(columns; {'-'.join(map(str, maps))} maps each, {st['window']} x {st['window']} cells, "
            f"{st['poses']} stops x {st['beams']} beams, {st['sweeps']} sweeps after {st['burn']}, kernel "
            f"{st['kernel']}): NLL in bits/cell, mean over the maps (min-max over the maps) / ROC AUC"
        ),
        header=["prior", *tests],
        rows=rows,
        provenance=doc["provenance"],
        note="a prior is never scored on a building of its training split (the leakage check runs first)",
    )


def _data_curve(doc: dict) -> Table:
    """``ogm-ppl fit-prior data-curve``: the PL pattern field's held-out score against the training plans."""
    rows = [
        [
            f"{r['plans']:,}",
            f"{r['validation_pll_bits']:.6f}",
            f"{r['train_pll_bits']:.6f}",
            _g(r["validation_windows_unseen_share"], 2),
            f"{r['distinct_neighbourhoods']:,}",
            f"{r['minutes_from_scratch']:.1f}",
        ]
        for r in doc["rows"]
    ]
    st = doc["settings"]
    return Table(
        caption=(
            f"The {st['w']} x {st['w']} pattern field (pseudo-likelihood, before tempering) fitted on a random "
            f"N of the {doc['provenance']['plans']:,} {doc['corpus']} training plans (nested samples, seed "
            f"{st['seed']}), scored on the same {st['validation']} other training plans: held-out and training "
            "pseudo-log-likelihood (bits/cell), the share of held-out 3 x 3 windows no training window showed, "
            "the distinct training neighbourhoods, and the minutes a fit of that size takes on 2 cores (reading "
            "the plans and fitting)"
        ),
        header=["plans", "held-out PLL", "training PLL", "unseen windows", "neighbourhoods", "minutes"],
        rows=rows,
        provenance=doc["provenance"],
    )


def _data_curve_guide(doc: dict) -> Table:
    """``ogm-ppl train-guide --curve-sizes``: the corpus guide's validation loss against the training plans."""
    rows = [
        [
            f"{r['plans']:,}",
            f"{r['training_plans_drawn']:,}",
            f"{r['validation_bits_per_unseen_cell_last']:.4f}",
            f"{r['validation_bits_per_unseen_cell_best']:.4f} ({r['kept_step']})",
            f"{r['validation_bits_per_unseen_cell_tempered']:.4f}",
            f"{r['train_bits_per_cell_tail']:.4f}",
            f"{r['minutes_data']:.1f} + {r['minutes_training']:.1f}",
        ]
        for r in doc["rows"]
    ]
    st, tr = doc["settings"], doc["settings"]["training"]
    return Table(
        caption=(
            f"The corpus guide trained on a random N of the {doc['training_split_plans']:,} {doc['corpus']} "
            f"training plans (nested samples, seed {st['seed']}; {tr['examples']:,} windows of {tr['window']} x "
            f"{tr['window']} cells drawn from them, {tr['steps']} steps of {tr['batch']}), every size validated on "
            f"the same {doc['validation_windows']} windows of the same {st['validation']} other training plans: "
            "the distinct plans the windows came from, the validation loss in bits per unseen near-mapped cell at "
            "the last step, at the best step (which) and after the temperature, the training loss (bits per "
            "scored cell, the last evaluations) and the minutes on 2 shared cores (data + training)"
        ),
        header=["plans", "drawn", "last step", "best (step)", "tempered", "training", "minutes"],
        rows=rows,
        provenance=doc["provenance"],
    )


def _calibration_guides(doc: dict) -> Table:
    """Each amortised guide (by the corpora it was learned on) on each test corpus, unseen cells: NLL, pooled
    ECE, ROC AUC and best F1."""
    tests, summ = _calibration_rows(doc, "unseen")
    keys = ("nll_bits", "ece_pooled", "auc", "best_f1")
    rows = _method_by_test(
        summ, tests, lambda s: s["prior"] == "guide", lambda s: " / ".join(_f(s.get(k)) for k in keys)
    )
    settings = doc["settings"]
    return Table(
        caption=(
            f"Guides on the unseen cells of held-out maps ({settings['plans']} per corpus, {settings['window']} x "
            f"{settings['window']} cells, {settings['poses']} stops x {settings['beams']} beams): NLL (bits/cell) / "
            "pooled ECE / ROC AUC / best F1, means over the maps"
        ),
        header=["guide", *tests],
        rows=rows,
        provenance=doc["provenance"],
        note="; ".join(
            n
            for n, on in (
                (
                    "guide:C1+C2: one guide learned on the training plans of those corpora",
                    any("+" in r[0] for r in rows),
                ),
                (
                    "@sym: its logits averaged over the 8 turns and flips of the window",
                    any("@sym" in r[0] for r in rows),
                ),
                (
                    f"guides read from {settings.get('guide_dir')}/guide_C.npz (trained by the command above)",
                    bool(settings.get("guide_dir")),
                ),
            )
            if on
        ),
    )


def _calibration_guides_spread(doc: dict) -> Table:
    """Each guide (and traditional OGM, the baseline) on each test set, unseen cells: NLL mean with its spread
    over the maps (min-max), ROC AUC and best F1 with theirs."""
    tests, summ = _calibration_rows(doc, "unseen")

    def cell(s: dict) -> str:
        sp = s.get("spread", {})
        return " / ".join(
            f"{_f(s[k])} ({_f(sp.get(k, {}).get('min'))}-{_f(sp.get(k, {}).get('max'))})"
            for k in ("nll_bits", "auc", "best_f1")
        )

    rows = _method_by_test(summ, tests, lambda s: s["prior"] in ("guide", "ogm"), cell)
    st = doc["settings"]
    maps = sorted({s["maps"] for s in summ})
    return Table(
        caption=(
            f"Guides per map: on the unseen cells of each test set ({'-'.join(map(str, maps))} maps, "
            f"{st['window']} x {st['window']} cells, {st['poses']} stops x {st['beams']} beams), NLL (bits/cell) / "
            "ROC AUC / best F1, each the mean over the maps (min-max over the maps)"
        ),
        header=["method", *tests],
        rows=rows,
        provenance=doc["provenance"],
        note="a guide is never scored on a building of the maps it was trained on (the leakage check runs first)",
    )


def _unseen_by_distance(doc: dict) -> Table:
    """``ogm-ppl study unseen_by_distance``: per test corpus and distance bin (cells to the nearest reached
    cell), the unseen cells' share, occupied share and the method's NLL; for a prior's chains also the chain
    length, the share of the bin's cells whose chains agree (split R-hat < 1.05) and each chain's mean
    occupancy there."""
    st = doc["settings"]
    chains = "prior" in st
    rows = []
    for r in doc["rows"]:
        lo, hi = r["distance"]
        span = f"({lo:g}, {'∞' if hi is None else f'{hi:g}'}]"
        row = [r["test"], span, _f(r["share"], 2), _f(r["occupied_share"], 2), _f(r["nll_bits"])]
        if chains:
            row[1:1] = [str(r["sweeps"])]
            row += [_f(r["agree"], 2), " / ".join(_f(v, 2) for v in r["chain_occupied"])]
        rows.append(row)
    header = ["test", "distance (cells)", "share", "occupied", "NLL"]
    if chains:
        header[1:1] = ["sweeps"]
        header += ["R-hat < 1.05", "chain occupancy (OGM / free / prior start)"]
        burn = "a quarter as many" if st.get("burn") is None else str(st["burn"])
        what = (
            f"{st['prior']} ({st['kernel']}, 3 chains from different starts, kept sweeps after {burn} warm-up sweeps)"
        )
    else:
        what = f"guide:{st['guide']}"
    if st.get("plan_files"):  # plans of other buildings: as many as ran, and how their unknown cells were read
        unknown = "unscored" if st.get("plan_outside") == "unknown" else "occupied"
        where = f"{doc['rows'][0]['maps']} plans of other buildings ({st['plan_set']}; their unknown cells {unknown})"
    else:
        where = f"{st['plans']} held-out maps per corpus"
    return Table(
        caption=(
            f"{what} on the unseen cells of {where}, by distance to the nearest cell a ray reached: share of the "
            "unseen cells, occupied share, NLL (bits/cell)" + (", chain agreement and occupancy" if chains else "")
        ),
        header=header,
        rows=rows,
        provenance=doc["provenance"],
    )


def _guide_limits(doc: dict) -> Table:
    """``ogm-ppl study guide_limits``: per guide, its NLL on the unseen cells of a test corpus's held-out maps,
    and the NLL after the temperature (and shift) that is best on those very maps; the guides' ensemble."""
    st = doc["settings"]
    rows = []
    for name, s in doc["summary"].items():
        if name == "ensemble":
            rows.append([f"mean of the {len(s['of'])} guides' probabilities", _f(s["nll"]), "–", "–"])
            continue
        T, b = s["oracle_affine"]
        rows.append(
            [
                name,
                _f(s["nll"]),
                f"{_f(s['nll_oracle_temperature'])} (T = {s['oracle_temperature']:g})",
                f"{_f(s['nll_oracle_affine'])} (T = {T:g}, b = {b:g})",
            ]
        )
    return Table(
        caption=(
            f"Guides on the unseen cells of {st['plans']} held-out {st['test']} maps (calibration protocol): NLL "
            "(bits/cell, mean over maps) as trained, and after the temperature T, or T and shift b (logit / T + b), "
            "that is best on these maps themselves (a bound on any recalibration)"
        ),
        header=["guide", "NLL", "best temperature", "best temperature and shift"],
        rows=rows,
        provenance=doc["provenance"],
    )


def _corpus_stats(doc: dict) -> Table:
    """``ogm-ppl corpus-stats`` of each floor-plan corpus: plans, cells, known and occupied share, walls."""
    rows = []
    for name, c in doc["corpora"].items():
        size = c["size"]
        rows.append(
            [
                f"`{name}`",
                f"{c['plans']:,}",
                f"{c['buildings']:,}",
                f"{c['cells'] / 1e6:,.1f} M",
                _f(c["known_share"]),
                _f(c["occupied_share"]),
                f"{c['wall_thickness_cells']['percentiles']['p50']:g}",
                f"{size['width']['p50']:.1f} x {size['height']['p50']:.1f}",
                _f(c["seconds_per_plan"]),
            ]
        )
    first = next(iter(doc["corpora"].values()))
    return Table(
        caption=(
            f"The floor-plan corpora as rasterised at {first['resolution_m']:g} m cells with the exterior "
            f"unknown (known share: of the grid with its {first['margin_cells']}-cell margin; "
            "occupied share: of the known cells; walls: the median run of occupied cells between two free cells; "
            "sizes: median, margins included)"
        ),
        header=[
            "corpus",
            "plans",
            "buildings",
            "cells",
            "known share",
            "occupied share",
            "walls (cells)",
            "median size (m)",
            "seconds a plan",
        ],
        rows=rows,
        provenance=doc["provenance"],
    )


def _prior_occupancy(doc: dict) -> Table:
    """``ogm-ppl study prior_occupancy``: each prior's occupied share on a window with no readings (the second
    half of three chains, and each chain's) against its training corpus's ``lambda``."""
    st = doc["settings"]
    fitted = bool(st.get("fit_bias"))
    rows = []
    for r in doc["rows"]:
        row = [
            r["prior"],
            _f(r["corpus_share"]),
            _f(r["share"]),
            _f(r["share"] - r["corpus_share"], 3),
            " / ".join(_f(v) for v in r["chain_shares"]),
        ]
        if fitted:
            f = r["fit"]
            row += [f"{f['bias']:+.3f}", _f(f["share"]), " / ".join(_f(v) for v in f["chain_shares"])]
        rows.append(row + [_f(r["seconds"], 0)])
    header = ["prior", "corpus", "prior's share", "difference", "chains (free / occupied / draw start)"]
    if fitted:
        header += ["bias h", "biased share", "biased chains"]
    return Table(
        caption=(
            f"Occupied share of a {st['window']} x {st['window']} window with no readings under each prior (its "
            f"mixing cycle, 3 chains of {st['sweeps']} sweeps from the all-free map, the all-occupied map and a prior "
            "draw; the mean over each chain's second half) against the occupied share of its training corpus "
            "(lambda of its tables)"
            + (
                f"; with the bias h fitted to it ({st['bias_steps']} bisection steps on [-{st['bias_range']:g}, "
                f"{st['bias_range']:g}], two chains each) and the biased prior's share"
                if fitted
                else ""
            )
        ),
        header=[*header, "seconds"],
        rows=rows,
        provenance=doc["provenance"],
    )


def _calibration_bias(doc: dict) -> Table:
    """A calibration run with ``--bias-file``: per prior it biased and test corpus (the prior learned there), the
    bias ``h``, and the unseen cells' NLL, ECE, AUC and share of cells with split R-hat < 1.05, the prior ->
    the prior times ``exp(h sum_k m_k)``."""
    st = doc["settings"]
    own = {(s["prior"], s["test"]): s for s in doc["summary"] if s["mask"] == "unseen" and s["train"] == s["test"]}
    tests = list(dict.fromkeys(t for _, t in own))
    rows = []
    for kind in st["priors"]:
        cells = []
        for t in tests:
            a, b = own.get((kind, t)), own.get((kind + "+bias", t))
            base, at, mod = kind.partition("@")
            h = st["bias"].get(f"{base}:{t}{at}{mod}")
            if a is None or b is None or h is None:
                cells += ["–"] * 4
                continue
            cells.append(f"{h:+.3f}")
            for key, d in (("nll_bits", 3), ("ece", 3), ("rhat_below", 2)):
                cells.append(f"{_f(a[key], d)} → {_f(b[key], d)}")
        rows.append([kind, *cells])
    return Table(
        caption=(
            f"Unseen cells of held-out maps ({st['plans']} per corpus), each prior learned on the test corpus and "
            f"biased by the h that fills an empty window as its corpus is filled ({st['kernel']}, 3 chains of "
            f"{st['sweeps']} sweeps): h, NLL (bits/cell), ECE and the share of cells with split R-hat < 1.05, the "
            "prior → the biased prior"
        ),
        header=["prior", *(f"{t} {m}" for t in tests for m in ("h", "NLL", "ECE", "R-hat < 1.05"))],
        rows=rows,
        provenance=doc["provenance"],
    )


#: Table 6.4's pooled best F1 in the thesis, by the algorithm names of the specs
_THESIS_6_4 = {"ogm": 0.9328, "dd-L1": 0.9460, "dd-L9": 0.9458, "border-L9": 0.9820, "border-thesis-L9": 0.9820}


def _calibration_kernels(
    doc: dict, against: str = "calibration_cycle_gibbs", seconds: bool = False, lengths: bool = False
) -> Table:
    """Two kernels on the same maps: the snapshot ``doc`` (a calibration run with one ``--kernel``) against
    the snapshot ``against`` (the same settings with another kernel; its priors may be more). Per prior of
    ``doc`` and test corpus (priors learned on it), the share of unseen cells whose split R-hat is below 1.05
    and the unseen cells' NLL, with ``seconds`` the seconds a map (three chains). ``lengths``: the chains may
    differ in length (``sweeps``, ``burn``) and ``doc`` may run on fewer test corpora."""
    base = load_snapshot(against)
    a, b = base["settings"], doc["settings"]
    free = ("kernel", "priors") + (("sweeps", "burn", "test") if lengths else ())
    differ = sorted(k for k in a.keys() | b.keys() if k not in free and a.get(k) != b.get(k))
    if not set(b["priors"]) <= set(a["priors"]) or not set(b["test"]) <= set(a["test"]):
        differ.append("priors or test corpora")
    if differ:
        raise ValueError(f"{against} and the {b.get('kernel')} snapshot differ in {differ}")
    kernels = (a.get("kernel", "gibbs"), b.get("kernel", "gibbs"))

    def own(d: dict) -> dict:
        return {(s["prior"], s["test"]): s for s in d["summary"] if s["mask"] == "unseen" and s["train"] == s["test"]}

    x, y = own(base), own(doc)
    tests = list(dict.fromkeys(t for _, t in y))
    order = b["priors"]
    rows = []
    for prior in sorted({p for p, _ in y}, key=lambda p: order.index(p) if p in order else len(order)):
        cells = []
        for t in tests:
            sa, sb = x.get((prior, t)), y.get((prior, t))
            for k, d in (("rhat_below", 2), ("nll_bits", 3), ("seconds", 0))[: 3 if seconds else 2]:
                cells.append("–" if sa is None or sb is None else f"{_f(sa[k], d)} → {_f(sb[k], d)}")
        rows.append([prior, *cells])
    chains = f"{b['sweeps']}" if a["sweeps"] == b["sweeps"] else f"{a['sweeps']} → {b['sweeps']}"
    measures = ("R-hat < 1.05", "NLL", "s / map")[: 3 if seconds else 2]
    return Table(
        caption=(
            f"Unseen cells of held-out maps ({b['plans']} per corpus), each prior learned on the test corpus, 3 chains "
            f"of {chains} sweeps from different starts: share of cells with split R-hat < 1.05 and NLL "
            f"(bits/cell){', seconds a map (three chains)' if seconds else ''}, kernel {kernels[0]} → {kernels[1]}"
        ),
        header=["prior", *(f"{t} {m}" for t in tests for m in measures)],
        rows=rows,
        provenance=_join_provenance(base["provenance"], doc["provenance"]),
    )


def _experiment_pooled(doc: dict) -> Table:
    """An experiment's pooled scores (every dataset's cells in one P-R curve), one row per algorithm: best F1
    with its precision and recall, ROC AUC, touched-cell best F1, the thesis's Table 6.4 figure, and the
    mean seconds of one run (one dataset, one chain)."""
    rows = []
    secs = _run_seconds(doc)
    for p in doc["pooled"]:
        m, t = p["mask"], p.get("touched") or {}
        thesis = _THESIS_6_4.get(p["algorithm"])
        rows.append(
            [
                p["algorithm"],
                _f(m["best_f1"]),
                _f(m["precision"]),
                _f(m["recall"]),
                _f(m["auc"]),
                _f(t.get("best_f1", float("nan"))),
                "–" if thesis is None else _f(thesis, 4),
                _f(secs.get(p["algorithm"]), 1),
            ]
        )
    n = len(doc["pooled"][0]["datasets"]) if doc["pooled"] else 0
    return Table(
        caption=f"{doc['experiment']}: pooled over {n} datasets, every cell scored (touched cells apart)",
        header=[
            "algorithm",
            "best F1",
            "precision",
            "recall",
            "ROC AUC",
            "touched best F1",
            "thesis best F1",
            "s / run",
        ],
        rows=rows,
        provenance=doc["provenance"],
    )


def _error_split(doc: dict) -> Table:
    """``ogm-ppl study table_6_4_errors``: each algorithm's pooled best F1 with its false positives and
    negatives among touched and never-touched cells, then the two oracle maps that know every touched cell."""
    rows = [
        [
            name,
            _f(s["best_f1"], 4),
            _f(s["threshold"], 2),
            f"{s['fp_touched']:,}",
            f"{s['fp_untouched']:,}",
            f"{s['fn_touched']:,}",
            f"{s['fn_untouched']:,}",
        ]
        for name, s in doc["algorithms"].items()
    ]
    rows += [[f"oracle: {name}", _f(f1, 4), "–", "–", "–", "–", "–"] for name, f1 in doc["oracles"].items()]
    n_u, occ_u = doc["cells"]["untouched"], doc["occupied"]["untouched"]
    return Table(
        caption=(
            f"pooled over {doc['datasets']} datasets: errors at the best threshold; {n_u:,} never-touched cells, "
            f"{n_u - occ_u:,} of them free"
        ),
        header=["map", "best F1", "threshold", "FP touched", "FP never touched", "FN touched", "FN never touched"],
        rows=rows,
        provenance=doc["provenance"],
    )


def _touched_errors(doc: dict) -> Table:
    """``ogm-ppl study touched_errors``: per dataset and map, the touched best F1, the walls missed and the
    false positives by distance to the nearest benchmark wall, the wall cells called occupied by depth."""
    rows = []
    for ds, algs in doc["datasets"].items():
        for name, r in algs.items():
            depth = r["walls_by_depth"]
            rows.append(
                [
                    ds,
                    name,
                    _f(r["touched_best_f1"]),
                    _f(r["threshold"], 2),
                    f"{r['false_negatives']:,}",
                    *(f"{r['fp_binned'][b]:,}" for b in ("1", "2-3", "4+")),
                    " / ".join(_f(depth[d]["called_occupied"], 2) if d in depth else "–" for d in ("1", "2")),
                ]
            )
    return Table(
        caption="touched cells at each map's best touched threshold: walls missed, false positives by chessboard "
        "distance to the nearest benchmark wall, and the share of the wall cells 1 / 2 deep called occupied",
        header=[
            "dataset",
            "map",
            "touched F1",
            "threshold",
            "walls missed",
            "FP at 1",
            "FP at 2-3",
            "FP at 4+",
            "wall depth 1 / 2",
        ],
        rows=rows,
        provenance=doc["provenance"],
    )


def _active(doc: dict) -> Table:
    """An ``active`` experiment (exploration): per rule, the median path length (m) to 90 % coverage, to best
    F1 0.8 and 0.9, with how many runs reach each, the paired ratios of the path to 90 % coverage to the
    first rule's (nearest frontier) and to ``ogm-ig``'s and ``ogm-ig-per-m``'s (the independent-cell
    information gain), the mean final best F1 and seconds a run."""
    from ogm_ppl.experiment.active import paired_ratio

    def path(x: float) -> str:
        return "never" if isinstance(x, float) and math.isinf(x) else _f(x, 2)

    runs = doc["runs"]
    refs = [x for x in ("ogm-ig", "ogm-ig-per-m") if any(r["method"] == x for r in runs)]  # those that ran
    rows = []
    for r in doc["summary"]:
        n = r["runs"]
        to_refs = [paired_ratio(runs, r["method"], ref, "coverage") for ref in refs]
        rows.append(
            [
                r["method"],
                f"{path(r['path_to_coverage'])} ({r['reached_coverage']}/{n})",
                f"{_f(r['ratio_coverage'])} ({r['pairs_coverage']})",
                *[f"{_f(rb)} ({nb})" for rb, nb in to_refs],
                f"{path(r['path_to_f1_0.8'])} ({r['reached_f1_0.8']}/{n})",
                f"{_f(r['ratio_f1_0.8'])} ({r['pairs_f1_0.8']})",
                f"{path(r['path_to_f1'])} ({r['reached_f1']}/{n})",
                f"{_f(r['ratio_f1'])} ({r['pairs_f1']})",
                _f(r["final_f1"]),
                _f(r["seconds"], 1),
            ]
        )
    nplans = len({x["plan_id"] for x in runs})
    nseeds = len({x["seed"] for x in runs})
    first = doc["summary"][0]["method"]
    return Table(
        caption=f"{doc['experiment']}: {nplans} held-out plans x {nseeds} seed(s); path length (m) to each level, "
        "median over runs (never: fewer than half reach it), runs reaching it in brackets",
        header=[
            "rule",
            "path to 90 % cov.",
            f"ratio to {first} (pairs)",
            *[f"ratio to {ref} (pairs)" for ref in refs],
            "path to F1 0.8",
            f"F1 0.8 ratio to {first}",
            "path to F1 0.9",
            f"F1 0.9 ratio to {first}",
            "final F1",
            "s / run",
        ],
        rows=rows,
        provenance=doc["provenance"],
        note="ratios: median over (plan, seed) pairs where both rules reach the level",
    )


def _active_d0(doc: dict) -> Table:
    """The distance offset ``d_0`` of the per-metre exploration rules chosen on validation plans
    (``ogm-ppl study tune_distance_offset``): per rule and offset, the median path length to 90 % coverage
    over the plans and the mean over the runs that reach it."""

    def path(x: float) -> str:
        return "never" if isinstance(x, float) and math.isinf(x) else _f(x, 2)

    rows = []
    for name, by in doc["summary"].items():
        for d0, v in by.items():
            mark = " (chosen)" if float(d0) == float(doc["chosen"][name]) else ""
            rows.append([name, d0 + mark, path(v["median_path_to_coverage_0.9"]), path(v["mean_reached"])])
    return Table(
        caption=f"d_0 on {len(doc['validation_plans'])} validation {doc['corpus']} plans (window {doc['window']}), "
        "never on held-out ones",
        header=["rule", "d_0 (m)", "median path to 90 % cov. (m)", "mean over runs reaching it (m)"],
        rows=rows,
        provenance=doc["provenance"],
        note=f"criterion: {doc['criterion']}",
    )


def _run_seconds(doc: dict) -> dict[str, float]:
    """Mean seconds of one run (one dataset, one chain) per algorithm of an experiment's ``runs``."""
    secs: dict[str, list[float]] = {}
    for r in doc.get("runs", []):
        secs.setdefault(r["algorithm"], []).append(float(r["seconds"]))
    return {a: sum(s) / len(s) for a, s in secs.items()}


def _experiment_conditions(doc: dict) -> Table:
    """An experiment's scores per condition (e.g. each pose fraction of one log), one row per algorithm: best
    F1 / ROC AUC / touched-cell best F1 on the mask, one column per condition (its share of the readings),
    and the mean seconds of one run."""
    cells, header = _by_condition(doc["pooled"])
    secs = _run_seconds(doc)
    return Table(
        caption=f"{doc['experiment']}: best F1 / ROC AUC / best F1 on the touched cells, per condition",
        header=["algorithm", *header, "s / run"],
        rows=[[a, *row, _f(secs.get(a), 1)] for a, row in cells.items()],
        provenance=doc["provenance"],
    )


def _experiment_by_log(doc: dict) -> Table:
    """An experiment over several logs, each at several pose fractions (conditions named ``ENTRY-pfF``): one
    row per log and algorithm, best F1 / ROC AUC / touched-cell best F1 on the mask, one column per pose
    fraction."""
    pooled = doc["pooled"]
    fracs = list(dict.fromkeys(p["condition"].removeprefix(p["entry"] + "-pf") for p in pooled))
    got = {(p["entry"], p["algorithm"], p["condition"].removeprefix(p["entry"] + "-pf")): p for p in pooled}
    rows = [
        [e, a, *(_f1_auc_touched(got.get((e, a, f))) for f in fracs)]
        for e in dict.fromkeys(p["entry"] for p in pooled)
        for a in dict.fromkeys(p["algorithm"] for p in pooled if p["entry"] == e)
    ]
    return Table(
        caption=f"{doc['experiment']}: best F1 / ROC AUC / best F1 on the touched cells, per log and pose share",
        header=["log", "algorithm", *(f"{100 * float(f):.3g} % of the poses" for f in fracs)],
        rows=rows,
        provenance=doc["provenance"],
    )


#: table name -> (snapshot name, builder)
def _path_free(doc: dict) -> Table:
    """``P(path free)``: the exact joint answer against the product of marginals, and both against the truth."""
    s = doc["settings"]
    rows = []
    for name, r in doc["summary"].items():
        for b in doc["by_length"][name]:
            rows.append(
                [
                    f"`{name}`",
                    str(b["length"]),
                    f"{b['paths']:,}",
                    _f(b["truth_free_share"]),
                    _f(b["exact_mean"]),
                    _f(b["independent_mean"]),
                    _f(b["mean_abs_error"]),
                    _f(b["log_loss_bits_exact"]),
                    _f(b["log_loss_bits_independent"]),
                ]
            )
        rows.append(
            [
                f"`{name}`",
                "all",
                f"{r['paths']:,}",
                _f(r["truth_free_share"]),
                "",
                "",
                f"{_f(r['independent_minus_exact_mean_abs'])} (max {_f(r['independent_minus_exact_max_abs'])})",
                _f(r["log_loss_bits"]["exact"]),
                _f(r["log_loss_bits"]["independent"]),
            ]
        )
    return Table(
        caption=(
            f"P(path free) of the straight paths (2 or more cells, at least one unseen) of {len(doc['scenes'])} "
            f"enumerable {s['rows']} x {s['cols']}-cell scenes cut from held-out {s['corpus']} plans "
            f"({s['beams']} beams of {s['range_cells']:g} cells): the exact posterior's answer, the product of its "
            "marginals, their mean absolute difference, and the log loss of each against the plan (bits a path)"
        ),
        header=[
            "prior",
            "length",
            "paths",
            "free in truth",
            "exact (mean)",
            "product (mean)",
            "abs. difference",
            "bits, exact",
            "bits, product",
        ],
        rows=rows,
        provenance=doc["provenance"],
    )


TABLES: dict[str, tuple[str, Callable[[dict], Table]]] = {
    "active_d0": ("active_d0", _active_d0),
    "active_full": ("active_full", _active),
    "active_medium": ("active_medium", _active),
    "bench_exact": ("bench_exact", _bench_exact),
    "bench_ogm": ("bench_ogm", _bench_ogm),
    "bench_parallel": ("bench_parallel", _bench_parallel),
    "bench_patch": ("bench_patch", _bench_patch),
    "bench_table_6_6": ("bench_table_6_6", _bench_table_6_6),
    "calibration": ("calibration", _calibration),
    "calibration_cross": ("calibration", _calibration_cross),
    "calibration_guides": ("calibration_guides", _calibration_targets),
    "calibration_guides_cross": ("calibration_guides", _calibration_cross),
    "calibration_guides_matrix": ("calibration_guides", _calibration_guides),
    "calibration_mix": ("calibration_mix", _calibration_guides),
    "calibration_generated": ("calibration_generated", _calibration_guides),
    "calibration_all": ("calibration_all", _calibration_guides),
    "calibration_real": ("calibration_real", _calibration_guides),
    "calibration_real_spread": ("calibration_real", _calibration_guides_spread),
    "calibration_real_logs": ("calibration_real_logs", _calibration_plans),
    "calibration_real_logs_spread": ("calibration_real_logs", _calibration_guides_spread),
    "calibration_logs": ("calibration_logs", _calibration_plans),
    "calibration_logs_occupied": ("calibration_logs_occupied", _calibration_plans),
    "calibration_logs_net": ("calibration_logs_net", _calibration_plans),
    "calibration_logs_net_guided": ("calibration_logs_net_guided", _calibration_plans),
    "calibration_cycle": ("calibration_cycle", _calibration_kernels),
    "guide_limits_ipa": ("guide_limits_ipa", _guide_limits),
    "unseen_by_distance": ("unseen_by_distance", _unseen_by_distance),
    "unseen_by_distance_chains": ("unseen_by_distance_chains", _unseen_by_distance),
    "unseen_by_distance_logs": ("unseen_by_distance_logs", _unseen_by_distance),
    "unseen_by_distance_logs_occupied": ("unseen_by_distance_logs_occupied", _unseen_by_distance),
    "prior_occupancy": ("prior_occupancy", _prior_occupancy),
    "corpus_stats": ("corpus_stats", _corpus_stats),
    "path_free": ("path_free", _path_free),
    "path_free_net": ("path_free_net", _path_free),
    "data_curve": ("data_curve", _data_curve),
    "data_curve_guide": ("data_curve_guide", _data_curve_guide),
    "data_curve_guide_small": ("data_curve_guide_small", _data_curve_guide),
    "calibration_corpora": ("calibration_corpora", _calibration_corpora),
    "calibration_corpora_logs": ("calibration_corpora_logs", _calibration_corpora),
    "calibration_corpora_cal": ("calibration_corpora_cal", _calibration_corpora),
    "calibration_corpora_logs_cal": ("calibration_corpora_logs_cal", _calibration_corpora),
    "calibration_bias": ("calibration_bias", _calibration_bias),
    "calibration_bias10": ("calibration_bias10", _calibration_bias),
    "prior_bias": ("prior_bias", _prior_occupancy),
    "calibration_shifted": ("calibration_shifted", lambda doc: _calibration_kernels(doc, "calibration_cycle")),
    "calibration_shifted_random": (
        "calibration_shifted_random",
        lambda doc: _calibration_kernels(doc, "calibration_shifted", seconds=True),
    ),
    "calibration_shifted_random400": (
        "calibration_shifted_random400",
        lambda doc: _calibration_kernels(doc, "calibration_shifted", seconds=True, lengths=True),
    ),
    "carmen_guide": ("carmen_guide", _experiment_by_log),
    "p_rand_logs": ("p_rand_logs", _experiment_by_log),
    "headline": ("headline", _headline),
    "intel_guide": ("intel_guide", _experiment_conditions),
    "intel_guide_2cm": ("intel_guide_2cm", _experiment_conditions),
    "intel_touched_errors": ("intel_touched_errors", _touched_errors),
    "simulated": ("headline", _simulated),
    "table_3_1": ("table_3_1", _table_3_1),
    "table_6_4_errors": ("table_6_4_errors", _error_split),
    "table_6_4_full": ("table_6_4_full", _experiment_pooled),
    "table_6_4_small": ("table_6_4_small", _experiment_pooled),
    "table_6_4_tempered": ("table_6_4_tempered", _experiment_pooled),
    "table_6_4_warm": ("table_6_4_warm", _experiment_pooled),
}


def table(name: str, results: Path = RESULTS) -> Table:
    """The table ``name`` (a key of :data:`TABLES`) built from its snapshot."""
    snap, build = TABLES[name]
    return build(load_snapshot(snap, results))


def _cell(text: str) -> str:
    return text.replace("|", "\\|")


def to_markdown(t: Table) -> str:
    """A GitHub-flavoured Markdown table and, under it, the line naming its command, commit and machine."""
    lines = ["| " + " | ".join(map(_cell, t.header)) + " |", "|" + "---|" * len(t.header)]
    lines += ["| " + " | ".join(map(_cell, r)) + " |" for r in t.rows]
    tail = provenance_line(t.provenance) + (f"; {t.note}" if t.note else "")
    return "\n".join([*lines, "", f"{t.caption}. From {tail}."])


# ------------------------------------------------------------------------------------------ the README
_BLOCK = re.compile(r"(<!-- generated: (?P<name>[a-z0-9_]+) -->\n)(?P<body>.*?)(<!-- end generated -->)", re.S)


def readme_block(name: str, results: Path = RESULTS) -> str:
    """The body of the README's ``<!-- generated: NAME -->`` block."""
    return to_markdown(table(name, results)) + "\n"


def update_readme(path: Path = README, results: Path = RESULTS, check: bool = False) -> list[str]:
    """Rewrite every generated block of ``path`` from the snapshots; returns the names of blocks that
    differed (with ``check``, nothing is written)."""
    from ogm_ppl.io import atomic_write_text

    text = path.read_text()
    stale = []

    def sub(m: re.Match) -> str:
        body = readme_block(m["name"], results)
        if body != m["body"]:
            stale.append(m["name"])
        return m.group(1) + body + m.group(4)

    new = _BLOCK.sub(sub, text)
    if stale and not check:
        atomic_write_text(path, new)
    return stale


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    s = sub.add_parser("snapshot", help="copy a result JSON into docs/results/, stamped")
    s.add_argument("src", type=Path)
    s.add_argument("--name")
    s.add_argument("--command", help="the command that produced SRC (for a JSON without provenance)")
    s.add_argument("--drop-curves", action="store_true", help="leave out the per-dataset P-R curves")
    mg = sub.add_parser("merge", help="add the algorithms of a later run of the same experiment (or its error split)")
    mg.add_argument("src", type=Path)
    mg.add_argument("--into", required=True, help="the snapshot (docs/results/INTO.json) to add them to")
    mg.add_argument("--command", required=True, help="the command that produced SRC")
    mg.add_argument("--drop-curves", action="store_true", help="leave out the per-dataset P-R curves")
    r = sub.add_parser("readme", help="rewrite the README's generated blocks")
    r.add_argument("--check", action="store_true", help="only report blocks that differ; exit 1 if any")
    r.add_argument("--readme", type=Path, default=README, help="the README to rewrite (the checkout's)")
    sh = sub.add_parser("show", help="print one table as Markdown")
    sh.add_argument("name", choices=sorted(TABLES))
    sub.add_parser("list", help="print each table's name and its snapshot's, one table a line")
    for p in (s, mg, r, sh):
        p.add_argument("--results", type=Path, default=RESULTS, help="the snapshots' folder (docs/results)")
    args = ap.parse_args(argv)
    try:
        if args.cmd == "snapshot":
            print("wrote", snapshot(args.src, args.name, args.command, args.results, drop_curves=args.drop_curves))
        elif args.cmd == "merge":
            print("wrote", merge(args.src, args.into, args.command, args.results, drop_curves=args.drop_curves))
        elif args.cmd == "readme":
            stale = update_readme(args.readme, args.results, check=args.check)
            print(("stale: " if args.check else "updated: ") + (", ".join(stale) or "none"))
            return 1 if (args.check and stale) else 0
        elif args.cmd == "list":
            print("\n".join(f"{name} {snap}" for name, (snap, _) in sorted(TABLES.items())))
        else:
            print(to_markdown(table(args.name, args.results)))
    except ValueError as e:
        print(f"gen_docs_tables.py: error: {e}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.path.insert(0, str(ROOT))
    raise SystemExit(main())
