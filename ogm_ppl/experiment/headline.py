r"""The headline experiment of ``make run`` / ``ogm-ppl run`` (:func:`run_headline`): the thesis's claim on
real, sparse data, then the simulated examples (:mod:`ogm_ppl.experiment.simple2d`).

A reduced Table 6.5 / Fig. 6.17 (Section 6.2.1): the Intel Lab log at 5 cm on the thesis's 30 m x 30 m
window, half the beams and half / 10 % of the poses (the thesis's Experiments 2 and 3), scored against the
thesis's benchmark (traditional OGM from all readings, thresholded at p > 0.20) on the near-mapped mask
(Fig. 6.16b), and on the cells each experiment's own readings touched. Algorithms: traditional OGM
(Hähnel), log-odds OGM with the p21 update term refitted for this sensor setting (Table 2.2 form, Section
2.5: the shipped p21 was fitted for 3-cell noise and a 75-cell range) and Gibbs sampling at L = 9 with the
learned prior that :func:`headline_prior` names: the one that mapped sparse simulated scans of held-out
*training* plans best (:func:`ogm_ppl.learn.select_headline_prior`, ``ogm-ppl fit-prior headline --ship``, writes
``ogm_ppl/fitted/headline_prior.json``;
the choice never looks at the Intel log, and the corpus holds no plan of the Intel building); and the one-pass
map of the amortised guide learned on the HouseExpo and IPA training plans (:data:`HEADLINE_GUIDE`, shipped,
trained for another sensor setting, so it warns), its logits averaged over the 8 turns and flips of the grid.

It is an ordinary experiment spec (:func:`headline_spec`) run by :func:`~ogm_ppl.experiment.run_experiment`
(dask, resumable); :func:`run_intel_headline` adds the summary table and a figure of the sparsest maps.
"""

from __future__ import annotations

import json
import os
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ogm_ppl.experiment.simple2d import run_simple2d
from ogm_ppl.io import atomic_write_text
from ogm_ppl.learn.headline import HEADLINE_PRIOR_FORMAT, UPDATES

__all__ = [
    "CHOSEN_BY",
    "HEADLINE_PRIOR_FORMAT",
    "INTEL_LOG",
    "HeadlinePrior",
    "find_shared_file",
    "headline_prior",
    "headline_spec",
    "run_headline",
    "run_intel_headline",
]

#: the Intel Lab log, relative to the shared data folder
INTEL_LOG = "intel-lab/intel-corrected.log.gz"
_HEADLINE_PRIOR = Path(__file__).resolve().parents[1] / "fitted" / "headline_prior.json"
_UPDATES = UPDATES
#: what the report names as the prior's chooser
CHOSEN_BY = "ogm-ppl fit-prior headline"
#: the corpus guide of the headline's one-pass row (:func:`~ogm_ppl.inference.variational.corpus_guide`)
HEADLINE_GUIDE = "houseexpo+ipa"


@dataclass(frozen=True)
class HeadlinePrior:
    """The headline's prior: ``name`` (``"KIND:CORPUS"`` for :func:`~ogm_ppl.priors.prior_by_name`), the
    patch-Gibbs ``update`` and the mean validation scores it was chosen by (``means``: candidate -> scores)."""

    kind: str
    corpus: str
    update: str
    means: dict

    @property
    def name(self) -> str:
        return f"{self.kind}:{self.corpus}"

    @property
    def label(self) -> str:
        how = ", the thesis's border update" if self.update == "thesis" else ""
        return f"Gibbs, {self.kind} prior ({self.corpus}{how}), L = 9"


def headline_prior(path: str | os.PathLike | None = None) -> HeadlinePrior:
    """Read and validate the selection that :func:`ogm_ppl.learn.select_headline_prior` (``ogm-ppl fit-prior
    headline``) wrote (default: the
    shipped ``ogm_ppl/fitted/headline_prior.json``). Raises ``ValueError`` naming the file and the field that
    is wrong (not JSON, another format, an unknown prior kind or corpus, an unknown update)."""
    from ogm_ppl.priors.named import prior_kinds
    from ogm_ppl.priors.tables import available_tables

    path = Path(path) if path is not None else _HEADLINE_PRIOR
    try:
        doc = json.loads(path.read_text())
    except (OSError, ValueError) as e:
        raise ValueError(f"{path}: cannot read the headline prior selection ({type(e).__name__}: {e})") from None
    if not isinstance(doc, dict) or doc.get("format") != HEADLINE_PRIOR_FORMAT:
        raise ValueError(f"{path}: not a headline prior selection (format must be {HEADLINE_PRIOR_FORMAT!r})")
    checks = (
        ("prior", prior_kinds()),
        ("corpus", tuple(available_tables())),
        ("update", _UPDATES),
    )
    for key, allowed in checks:
        if doc.get(key) not in allowed:
            raise ValueError(f"{path}: {key!r} is {doc.get(key)!r}; one of {', '.join(map(str, allowed))} expected")
    means = doc.get("means", {})
    if not isinstance(means, dict):
        raise ValueError(f"{path}: 'means' is not an object")
    return HeadlinePrior(doc["prior"], doc["corpus"], doc["update"], means)


def find_shared_file(relative: str) -> Path | None:
    """``relative`` under the shared data folder: ``$OGM_PPL_DATA``, else ``../shared/data`` beside the
    checkout (``shared/data`` in the folder that holds the repository); ``None`` if neither holds it."""
    roots = []
    if os.environ.get("OGM_PPL_DATA"):
        roots.append(Path(os.environ["OGM_PPL_DATA"]))
    roots.append(Path(__file__).resolve().parents[3] / "shared" / "data")
    for root in roots:
        if (root / relative).is_file():
            return root / relative
    return None


def headline_spec(
    log: str | os.PathLike,
    *,
    quick: bool = False,
    sigma_cells: float = 0.5,
    sweeps: int = 60,
    prior: HeadlinePrior | None = None,
) -> dict:
    """The headline spec as a dict (:func:`~ogm_ppl.experiment.parse_spec` validates it).

    ``quick`` (tests): 10 cm cells, only the 10 % subset, 6 sweeps. ``sigma_cells``: range noise of the
    Gibbs sensor model in cells (default 0.5 cell = 2.5 cm; see the README's Intel section for why not 3).
    ``prior``: the Gibbs prior (default :func:`headline_prior`, the shipped selection).
    """
    prior = headline_prior() if prior is None else prior
    res, fractions, n = (0.10, [0.1], 6) if quick else (0.05, [0.5, 0.1], sweeps)
    gibbs = {
        "kind": "gibbs",
        "patch": [3, 3],
        "sweeps": n,
        "burn_in": max(1, n // 6),
        "checkpoint_every": 5,
        "record": 3,
        "sigma_cells": float(sigma_cells),
        "update": prior.update,
    }
    return {
        "experiment": {
            "name": "intel_headline",
            "seed": 2020,
            "description": (
                "Real, sparse data (thesis Table 6.5 / Fig. 6.17, reduced): Intel Lab, half the beams "
                "with half / 10 % of the poses, against the p > 0.20 benchmark from all readings."
            ),
        },
        "datasets": [
            {
                "name": "intel",
                "kind": "log",
                "path": str(Path(log).resolve()),
                "reader": {"max_usable_range": 20.0},
                "resolution": res,
                "extent": [-10.9, -23.65, 30.0, 30.0],
                "sigma_cells": float(sigma_cells),
                "pose_fraction": fractions,
                "beam_step": 2,
                "benchmark": {"delta": "haehnel", "threshold": 0.20, "prior": 0.5},
            }
        ],
        "algorithms": [
            {"name": "ogm", "kind": "ogm", "delta": "haehnel"},
            {"name": "p21", "kind": "ogm", "delta": "p21", "fit": "setting"},
            {"name": "learned-L9", "prior": prior.name, **gibbs},
            {"name": "guide", "kind": "amortised", "guide": f"corpus:{HEADLINE_GUIDE}", "symmetrize": True},
        ],
        "metrics": {
            "mask": "near_mapped",
            "near_mapped_distance": 10.0,
            "touched_only": True,
            "thresholds": 99,
            "scores": ["f1", "auc", "max_precision"],
        },
        "output": {"maps": True, "figures": True, "fpfn": "none", "dpi": 90},
    }


LABELS = {
    "ogm": "traditional OGM (Hähnel)",
    "p21": "log-odds OGM, p21 fitted for this sensor",
    "guide": "amortised guide learned on HouseExpo + IPA plans, one pass, symmetrised",
}


def _label(name: str, prior: HeadlinePrior | None = None) -> str:
    if name == "learned-L9" and prior is not None:
        return prior.label
    return LABELS.get(name, name)


def _maps_figure(result, out: Path, prior: HeadlinePrior) -> Path:
    """The sparsest experiment's maps beside the benchmark (Fig. 6.13-6.15 style)."""
    from ogm_ppl.experiment.figures import _plt, _save_closed
    from ogm_ppl.experiment.tasks import base_dir, score_path
    from ogm_ppl.viz import plot_map

    plt = _plt()
    spec = result.spec
    ds = min(spec.datasets, key=lambda d: d.measurement_fraction)
    with np.load(base_dir(result.out_dir) / f"{ds.base}.npz", allow_pickle=False) as z:
        truth = z["truth"].astype(float)
    algs = [a for a in spec.algorithms if score_path(result.out_dir, ds, a).with_suffix(".npz").exists()]
    fig, axes = plt.subplots(1, 1 + len(algs), figsize=(4.2 * (1 + len(algs)), 4.4))
    plot_map(truth, None, axes[0], "benchmark (all readings, p > 0.20)", colorbar=False)
    for ax, a in zip(axes[1:], algs):
        with np.load(score_path(result.out_dir, ds, a).with_suffix(".npz"), allow_pickle=False) as z:
            q = z["marginals"]
        plot_map(
            q,
            None,
            ax,
            f"{_label(a.name, prior)}\n{100 * ds.measurement_fraction:.3g} % of readings",
            colorbar=False,
        )
    fig.tight_layout()
    return _save_closed(plt, fig, out / "intel_maps.png", 90)


def _table(result, prior: HeadlinePrior) -> list[str]:
    conds = list(dict.fromkeys(p["condition"] for p in result.pooled))
    frac = {p["condition"]: p["measurement_fraction"] for p in result.pooled}
    what = "F1 / AUC / touched F1 / seconds per map"
    head = "| map | " + " | ".join(f"{100 * frac[c]:.3g} % of readings: {what}" for c in conds) + " |"
    lines = [head, "|---" * (1 + len(conds)) + "|"]
    for a in result.spec.algorithms:
        cells = []
        for c in conds:
            p = next((p for p in result.pooled if p["condition"] == c and p["algorithm"] == a.name), None)
            if p is None:
                cells.append("–")
                continue
            m, t = p["mask"], p.get("touched", {})
            sec = _seconds_per_map(result.runs, p)
            cells.append(
                f"{m['best_f1']:.3f} / {m.get('auc', float('nan')):.3f} / {t.get('best_f1', float('nan')):.3f} / "
                + ("–" if sec is None else f"{sec:.2g} s")
            )
        lines.append(f"| {_label(a.name, prior)} | " + " | ".join(cells) + " |")
    return lines


def run_intel_headline(
    out: str | os.PathLike,
    log: str | os.PathLike | None = None,
    *,
    quick: bool = False,
    scheduler=None,
    workers: int | None = None,
    progress: bool = False,
) -> dict:
    """Run the headline spec into ``out/intel`` and return ``{"markdown": [...], "json": {...}}`` for the report.

    ``log``: the Intel Lab log (default: :func:`find_shared_file` of :data:`INTEL_LOG`); raises
    ``FileNotFoundError`` naming the places searched if there is none.
    """
    from ogm_ppl.experiment import parse_spec, run_experiment

    out = Path(out)
    if log is None:
        log = find_shared_file(INTEL_LOG)
        if log is None:
            raise FileNotFoundError(
                f"the Intel Lab log ({INTEL_LOG}) is not under $OGM_PPL_DATA or ../shared/data beside the "
                "checkout; pass --log PATH"
            )
    prior = headline_prior()
    spec = parse_spec(headline_spec(log, quick=quick, prior=prior), "<headline>")
    t0 = time.perf_counter()
    result = run_experiment(spec, out / "intel", scheduler=scheduler, workers=workers, progress=progress)
    seconds = time.perf_counter() - t0
    fig = _maps_figure(result, out, prior)
    ds0 = spec.datasets[0]
    p = ds0.params
    gib = next(a for a in spec.algorithms if a.records_metrics).params  # the sampler of the spec
    md = [
        "## Real data: the Intel Lab log, sparse (thesis Table 6.5 / Fig. 6.17, reduced)",
        "",
        f"{p['resolution'] * 100:g} cm cells on the thesis's 30 m x 30 m window, half the beams, "
        + ", ".join(f"{100 * d.params['pose_fraction']:g} %" for d in spec.datasets)
        + " of the poses. Benchmark: traditional OGM from all readings, p > 0.20; scored over the cells within "
        "10 cells of a benchmark-mapped cell (Fig. 6.16b) and over the cells the experiment's readings touched. "
        f"Gibbs: {gib['sweeps']} sweeps after {gib['burn_in']} burn-in from the thresholded OGM map, "
        f"sigma {p['sigma_cells']:g} cell(s). Prior: {prior.name} (update {prior.update}), chosen by "
        f"`{CHOSEN_BY}` (`ogm_ppl.learn.select_headline_prior`) on sparse simulated scans of held-out training plans "
        "(never on this log; the corpus holds no plan of the Intel building).",
        "",
        *_table(result, prior),
        "",
        f"Run time {seconds:.0f} s. Figures: `intel_maps.png` (the sparsest experiment's maps beside the benchmark), "
        "`intel/figures/` (P-R curves, F1 against threshold, sparsity and time); tables: `intel/metrics.md`.",
        "",
    ]
    doc = {
        "seconds": seconds,
        "pooled": [
            {k: v for k, v in r.items() if k not in ("mask", "touched")}
            | {"mask": _summary(r["mask"]), "touched": _summary(r.get("touched", {}))}
            | {"seconds_per_map": _seconds_per_map(result.runs, r)}
            for r in result.pooled
        ],
        "figure": str(fig),
        "prior": {"name": prior.name, "update": prior.update, "chosen_by": CHOSEN_BY},
    }
    atomic_write_text(out / "intel_headline.json", json.dumps(doc, indent=1, default=str, allow_nan=True))
    return {"markdown": md, "json": doc}


def _seconds_per_map(runs: list, pooled: dict) -> float | None:
    """Mean seconds of one map (one chain: the method's run, compiling excluded) of ``pooled``'s algorithm
    over its condition's datasets; ``None`` where no run record holds its time."""
    t = [r["seconds"] for r in runs if r["algorithm"] == pooled["algorithm"] and r["dataset"] in pooled["datasets"]]
    return float(sum(t) / len(t)) if t else None


def _summary(block: dict) -> dict:
    return {k: block[k] for k in ("best_f1", "threshold", "precision", "recall", "auc", "max_precision") if k in block}


def run_headline(
    out: str | os.PathLike,
    seed: int = 0,
    log: str | os.PathLike | None = None,
    quick: bool = False,
    scheduler=None,
    workers: int | None = None,
    progress: bool = False,
) -> dict:
    """What ``make run`` does: the real-data headline (:mod:`ogm_ppl.experiment.headline`: the Intel Lab
    log, sparse, traditional OGM against Gibbs with the learned prior of :func:`headline_prior`) and the
    simulated examples; writes the figures, ``report.md`` and ``report.json`` into ``out``.

    Without the Intel log (no ``log`` and none under the shared data folder) the report says so and holds
    the simulated part only.
    """
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    lines = ["# ogm_ppl headline run", ""]
    report: dict = {}
    try:
        intel = run_intel_headline(out, log, quick=quick, scheduler=scheduler, workers=workers, progress=progress)
        lines += intel["markdown"]
        report["intel"] = intel["json"]
    except FileNotFoundError as e:
        if log is not None:
            raise
        lines += ["## Real data: skipped", "", f"{e}.", ""]
        report["intel"] = {"skipped": str(e)}
        print(f"ogm-ppl run: {e}; running the simulated part only", file=sys.stderr)
    simple = run_simple2d(out, seed)
    lines += simple.pop("markdown")
    report.update(simple)
    report["seconds"] = time.perf_counter() - t0
    lines += [f"Total {report['seconds']:.0f} s.", ""]
    atomic_write_text(out / "report.json", json.dumps(report, indent=2, default=str, allow_nan=True))
    atomic_write_text(out / "report.md", "\n".join(lines))
    return report
