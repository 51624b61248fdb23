"""The tables of the calibration protocol (held-out plans, log plans, guides, corpora, data curves, biases and
kernels; ``tools/gen_docs_tables.py``)."""

from __future__ import annotations

from docs_tables_common import Table, _f, _g, join_provenance, load_snapshot


def _calibration_rows(doc: dict, mask: str) -> tuple[list[str], list[dict]]:
    summ = [s for s in doc["summary"] if s["mask"] == mask]
    return list(dict.fromkeys(s["test"] for s in summ)), summ


def calibration_table(doc: dict) -> Table:
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


def calibration_targets_table(doc: dict) -> Table:
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


def calibration_plans_table(doc: dict) -> Table:
    """``calibration.py --plan-files``: every method on the plan set's unseen cells (no prior was learned on
    those buildings, so every training corpus's priors and every guide are listed), as
    :func:`calibration_targets_table` lists a corpus's own."""
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


def calibration_cross_table(doc: dict) -> Table:
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


def calibration_corpora_table(doc: dict) -> Table:
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


def data_curve_table(doc: dict) -> Table:
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


def data_curve_guide_table(doc: dict) -> Table:
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


def calibration_guides_table(doc: dict) -> Table:
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


def calibration_guides_spread_table(doc: dict) -> Table:
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


def unseen_by_distance_table(doc: dict) -> Table:
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


def guide_limits_table(doc: dict) -> Table:
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


def corpus_stats_table(doc: dict) -> Table:
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


def prior_occupancy_table(doc: dict) -> Table:
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


def calibration_bias_table(doc: dict) -> Table:
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


def calibration_kernels_table(
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
        provenance=join_provenance(base["provenance"], doc["provenance"]),
    )


def temper_net_table(doc: dict) -> Table:
    """``ogm-ppl fit-prior temper --kinds net``: each exponent's unseen-cell NLL on the net's own validation plans,
    the share of cells whose chains agree (split R-hat < 1.05), and its prior samples' statistics from the all-free
    and the all-occupied start beside the validation plans'."""
    v = doc["validation"]

    def runs(s: dict) -> str:
        o, f = s.get("occupied_run"), s.get("free_run")
        return "–" if o is None or f is None else f"{o:.1f} / {f:.1f}"

    rows = []
    for beta, nll, agree, ps in zip(v["betas"], v["mean_nll_bits"], v["rhat_below"], v["prior_samples"], strict=True):
        free, occ = ps["free"], ps["occupied"]
        frozen = free["occupied"] == 0.0 and occ["occupied"] == 1.0
        mark = "**" if beta == doc["beta"] else ""
        rows.append(
            [
                f"{mark}{beta:g}{mark}",
                f"{mark}{_f(nll)}{mark}",
                f"{agree * 100:.0f} %",
                f"{_f(free['occupied'])} / {_f(occ['occupied'])}",
                "frozen at the starts" if frozen else f"{runs(free)} (from all-free)",
            ]
        )
    plan = v["validation_plan_statistics"]
    rows.append(["validation plans", "", "", _f(plan["occupied"]), runs(plan)])
    check = v["prior_sample_check"]
    return Table(
        caption=(
            f"`net:{doc['corpus']}@BETA` on the plans its fit kept for validation: the unseen cells' NLL (bits per "
            "cell, the chains pooled), the cells whose chains agree (split R-hat < 1.05), and prior samples "
            f"({check['chains']} chains of {check['size']} x {check['size']} cells, {check['sweeps']} sweeps, "
            f"{check['edge']} cells from the edges left out) from the all-free / all-occupied map: occupied share, "
            f"occupied / free run lengths in cells; bold: the exponent chosen ({doc['criterion']})"
        ),
        header=["beta", "unseen NLL, bits", "cells whose chains agree", "occupied share", "occupied / free run"],
        rows=rows,
        provenance=doc["provenance"],
        note=doc["provenance"].get("note", ""),
    )
