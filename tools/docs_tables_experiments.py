"""The tables of the experiment runs (pooled and per-log metrics, error splits, active mapping, P(path free);
``tools/gen_docs_tables.py``)."""

from __future__ import annotations

import math

from docs_tables_bench import by_condition, f1_auc_touched
from docs_tables_common import Table, _f

#: Table 6.4's pooled best F1 in the thesis, by the algorithm names of the specs
THESIS_6_4 = {"ogm": 0.9328, "dd-L1": 0.9460, "dd-L9": 0.9458, "border-L9": 0.9820, "border-thesis-L9": 0.9820}


def experiment_pooled_table(doc: dict) -> Table:
    """An experiment's pooled scores (every dataset's cells in one P-R curve), one row per algorithm: best F1
    with its precision and recall, ROC AUC, touched-cell best F1, the thesis's Table 6.4 figure, and the
    mean seconds of one run (one dataset, one chain)."""
    rows = []
    secs = _run_seconds(doc)
    for p in doc["pooled"]:
        m, t = p["mask"], p.get("touched") or {}
        thesis = THESIS_6_4.get(p["algorithm"])
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


def error_split_table(doc: dict) -> Table:
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


def touched_errors_table(doc: dict) -> Table:
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


def active_table(doc: dict) -> Table:
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


def active_d0_table(doc: dict) -> Table:
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


def experiment_conditions_table(doc: dict) -> Table:
    """An experiment's scores per condition (e.g. each pose fraction of one log), one row per algorithm: best
    F1 / ROC AUC / touched-cell best F1 on the mask, one column per condition (its share of the readings),
    and the mean seconds of one run."""
    cells, header = by_condition(doc["pooled"])
    secs = _run_seconds(doc)
    return Table(
        caption=f"{doc['experiment']}: best F1 / ROC AUC / best F1 on the touched cells, per condition",
        header=["algorithm", *header, "s / run"],
        rows=[[a, *row, _f(secs.get(a), 1)] for a, row in cells.items()],
        provenance=doc["provenance"],
    )


def experiment_by_log_table(doc: dict) -> Table:
    """An experiment over several logs, each at several pose fractions (conditions named ``ENTRY-pfF``): one
    row per log and algorithm, best F1 / ROC AUC / touched-cell best F1 on the mask, one column per pose
    fraction."""
    pooled = doc["pooled"]
    fracs = list(dict.fromkeys(p["condition"].removeprefix(p["entry"] + "-pf") for p in pooled))
    got = {(p["entry"], p["algorithm"], p["condition"].removeprefix(p["entry"] + "-pf")): p for p in pooled}
    rows = [
        [e, a, *(f1_auc_touched(got.get((e, a, f))) for f in fracs)]
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
def path_free_table(doc: dict) -> Table:
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
