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

The tables are built by ``docs_tables_bench.py`` (headline, simulated logs, benchmarks, Table 3.1),
``docs_tables_calibration.py`` (the calibration protocol), ``docs_tables_experiments.py`` (experiment runs) on
``docs_tables_common.py`` (:class:`Table`, snapshots' validation, number formats); :data:`TABLES` names them.

The Sphinx extension ``docs/_ext/ogm_tables.py`` renders the same :class:`Table` objects into the pages
(``{ogm-table} NAME``); ``tests/test_docs.py`` runs these commands (``readme --check``, ``list``, ``show``, and
``snapshot`` and ``merge`` into a folder of its own).
"""

from __future__ import annotations

import argparse
import datetime
import json
import re
import sys
from collections.abc import Callable
from pathlib import Path

from docs_tables_bench import (
    bench_exact_table,
    bench_ogm_table,
    bench_parallel_table,
    bench_patch_table,
    bench_table_6_6_table,
    headline_table,
    simulated_table,
    table_3_1_table,
)
from docs_tables_calibration import (
    calibration_bias_table,
    calibration_corpora_table,
    calibration_cross_table,
    calibration_guides_spread_table,
    calibration_guides_table,
    calibration_kernels_table,
    calibration_plans_table,
    calibration_table,
    calibration_targets_table,
    corpus_stats_table,
    data_curve_guide_table,
    data_curve_table,
    guide_limits_table,
    prior_occupancy_table,
    temper_net_table,
    unseen_by_distance_table,
)
from docs_tables_common import RESULTS, ROOT, Table, join_provenance, load_snapshot
from docs_tables_experiments import (
    active_d0_table,
    active_table,
    error_split_table,
    experiment_by_log_table,
    experiment_conditions_table,
    experiment_pooled_table,
    path_free_table,
    touched_errors_table,
)

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


# ------------------------------------------------------------------------------------------ snapshots


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
    out["provenance"] = join_provenance(base["provenance"], new["provenance"])
    return atomic_write_text(results / f"{into}.json", json.dumps(out, indent=1, allow_nan=True))


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


TABLES: dict[str, tuple[str, Callable[[dict], Table]]] = {
    "active_d0": ("active_d0", active_d0_table),
    "active_full": ("active_full", active_table),
    "active_medium": ("active_medium", active_table),
    "bench_exact": ("bench_exact", bench_exact_table),
    "bench_ogm": ("bench_ogm", bench_ogm_table),
    "bench_parallel": ("bench_parallel", bench_parallel_table),
    "bench_patch": ("bench_patch", bench_patch_table),
    "bench_table_6_6": ("bench_table_6_6", bench_table_6_6_table),
    "calibration": ("calibration", calibration_table),
    "calibration_cross": ("calibration", calibration_cross_table),
    "calibration_guides": ("calibration_guides", calibration_targets_table),
    "calibration_guides_cross": ("calibration_guides", calibration_cross_table),
    "calibration_guides_matrix": ("calibration_guides", calibration_guides_table),
    "calibration_mix": ("calibration_mix", calibration_guides_table),
    "calibration_generated": ("calibration_generated", calibration_guides_table),
    "calibration_all": ("calibration_all", calibration_guides_table),
    "calibration_real": ("calibration_real", calibration_guides_table),
    "calibration_real_spread": ("calibration_real", calibration_guides_spread_table),
    "calibration_real_logs": ("calibration_real_logs", calibration_plans_table),
    "calibration_real_logs_spread": ("calibration_real_logs", calibration_guides_spread_table),
    "calibration_logs": ("calibration_logs", calibration_plans_table),
    "calibration_logs_occupied": ("calibration_logs_occupied", calibration_plans_table),
    "calibration_logs_net": ("calibration_logs_net", calibration_plans_table),
    "calibration_logs_net_guided": ("calibration_logs_net_guided", calibration_plans_table),
    "calibration_logs_net_tempered": ("calibration_logs_net_tempered", calibration_plans_table),
    "calibration_cycle": ("calibration_cycle", calibration_kernels_table),
    "guide_limits_ipa": ("guide_limits_ipa", guide_limits_table),
    "unseen_by_distance": ("unseen_by_distance", unseen_by_distance_table),
    "unseen_by_distance_chains": ("unseen_by_distance_chains", unseen_by_distance_table),
    "unseen_by_distance_logs": ("unseen_by_distance_logs", unseen_by_distance_table),
    "unseen_by_distance_logs_occupied": ("unseen_by_distance_logs_occupied", unseen_by_distance_table),
    "prior_occupancy": ("prior_occupancy", prior_occupancy_table),
    "corpus_stats": ("corpus_stats", corpus_stats_table),
    "path_free": ("path_free", path_free_table),
    "path_free_net": ("path_free_net", path_free_table),
    "data_curve": ("data_curve", data_curve_table),
    "temper_net": ("temper_net", temper_net_table),
    "data_curve_guide": ("data_curve_guide", data_curve_guide_table),
    "data_curve_guide_small": ("data_curve_guide_small", data_curve_guide_table),
    "calibration_corpora_cal": ("calibration_corpora_cal", calibration_corpora_table),
    "calibration_corpora_logs_cal": ("calibration_corpora_logs_cal", calibration_corpora_table),
    "calibration_corpora": ("calibration_corpora", calibration_corpora_table),
    "calibration_corpora_logs": ("calibration_corpora_logs", calibration_corpora_table),
    "calibration_bias": ("calibration_bias", calibration_bias_table),
    "calibration_bias10": ("calibration_bias10", calibration_bias_table),
    "prior_bias": ("prior_bias", prior_occupancy_table),
    "calibration_shifted": ("calibration_shifted", lambda doc: calibration_kernels_table(doc, "calibration_cycle")),
    "calibration_shifted_random": (
        "calibration_shifted_random",
        lambda doc: calibration_kernels_table(doc, "calibration_shifted", seconds=True),
    ),
    "calibration_shifted_random400": (
        "calibration_shifted_random400",
        lambda doc: calibration_kernels_table(doc, "calibration_shifted", seconds=True, lengths=True),
    ),
    "carmen_guide": ("carmen_guide", experiment_by_log_table),
    "p_rand_logs": ("p_rand_logs", experiment_by_log_table),
    "headline": ("headline", headline_table),
    "intel_guide": ("intel_guide", experiment_conditions_table),
    "intel_guide_2cm": ("intel_guide_2cm", experiment_conditions_table),
    "intel_touched_errors": ("intel_touched_errors", touched_errors_table),
    "simulated": ("headline", simulated_table),
    "table_3_1": ("table_3_1", table_3_1_table),
    "table_6_4_errors": ("table_6_4_errors", error_split_table),
    "table_6_4_full": ("table_6_4_full", experiment_pooled_table),
    "table_6_4_small": ("table_6_4_small", experiment_pooled_table),
    "table_6_4_tempered": ("table_6_4_tempered", experiment_pooled_table),
    "table_6_4_warm": ("table_6_4_warm", experiment_pooled_table),
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
