"""The tables of the headline run, the simulated logs, the benchmarks and Table 3.1 (``tools/gen_docs_tables.py``)."""

from __future__ import annotations

from docs_tables_common import Table, _f, _g, _rate

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


def by_condition(pooled: list[dict]) -> tuple[dict[str, list[str]], list[str]]:
    """An experiment's pooled rows as ``best F1 / AUC / touched best F1`` per algorithm (in order of first
    appearance), one entry per condition (``"–"`` where the algorithm did not run), and the column headers
    (each condition's share of the readings)."""
    conds = list(dict.fromkeys(p["condition"] for p in pooled))
    frac = {p["condition"]: p["measurement_fraction"] for p in pooled}
    got = {(p["algorithm"], p["condition"]): p for p in pooled}
    cells = {a: [f1_auc_touched(got.get((a, c))) for c in conds] for a in dict.fromkeys(p["algorithm"] for p in pooled)}
    return cells, [f"{100 * frac[c]:.3g} % of the readings" for c in conds]


def f1_auc_touched(p: dict | None) -> str:
    """One pooled row as ``best F1 / AUC / touched best F1`` on the mask (then `` / seconds per map`` where the
    row holds it); ``"–"`` for a run that did not happen."""
    if p is None:
        return "–"
    t = p.get("touched") or {}
    cell = f"{_f(p['mask'].get('best_f1'))} / {_f(p['mask'].get('auc'))} / {_f(t.get('best_f1'))}"
    if p.get("seconds_per_map") is not None:
        cell += f" / {p['seconds_per_map']:.2g} s"
    return cell


def headline_table(doc: dict) -> Table:
    cells, header = by_condition(doc["intel"]["pooled"])
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


def simulated_table(doc: dict) -> Table:
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


def bench_ogm_table(doc: dict) -> Table:
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


def bench_exact_table(doc: dict) -> Table:
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


def bench_patch_table(doc: dict) -> Table:
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


def bench_table_6_6_table(doc: dict) -> Table:
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


def bench_parallel_table(doc: dict) -> Table:
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


def table_3_1_table(doc: dict) -> Table:
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
