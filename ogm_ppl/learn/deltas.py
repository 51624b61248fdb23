r"""Update terms Delta of traditional OGM fitted against exact 1D posteriors (thesis Sections 2.4-2.5).

Traditional OGM adds an update term ``Delta`` to the log-odds of every cell on a reading's ray (Section 2.4,
Eq. 2.10; :mod:`ogm_ppl.models.delta`). Section 2.5 fits its parameters ``theta`` as an amortised
mean-field posterior: over ``D`` datasets of a stationary robot before a wall
(:func:`~ogm_ppl.datasets.wall_datasets`: a wall at cell ``wall`` of ``F``, readings ``round(N(wall,
sigma^2))``, 1..10 each), whose exact posterior marginals ``p(m_k | z^(d))`` are known, it minimises the mean
summed cell cross-entropy

.. math:: \hat\theta = \arg\min_\theta \frac{1}{D}\sum_{d=1}^{D}\sum_{k=1}^{F}
          H\Bigl(p(m_k \mid z^{(d)}),\ \sigma\bigl(\textstyle\sum_n \Delta_\theta(k; z^{(d)}_n)\bigr)\Bigr)

by L-BFGS with a strong-Wolfe line search (:func:`~ogm_ppl.inference.variational.delta_fit.fit_delta`,
at most 500 iterations, gradient tolerance 1e-10; deterministic: the same seed gives the same numbers).

:func:`fit_deltas` fits every family of Table 2.1 (Borenstein-Koren, Moravec from Hähnel's values,
Marshall-Barfoot at each integer ``beta`` in 1..5, the best kept, Stachniss, Elfes), pN for N = 1..21 (each
started from the fitted p(N-1), :func:`~ogm_ppl.inference.variational.delta_fit.warm_start_pn`) and a small
network (:class:`~ogm_ppl.models.delta.NeuralDelta`, 16 hidden units, seed 0) on the datasets of the
shipped setting (``F = 75``, ``wall = 60``, ``sigma = 3`` cells, 1000 datasets, seed 0), scores them by
``folds``-fold cross-validation (fold ``k`` = datasets ``k s .. (k + 1) s - 1``, ``s = D // folds``, held
out, the rest fitted; the shipped terms ``haehnel``, ``moravec_thesis``, ``elfes_thesis``, ``p21_thesis`` as
references), and fits ``p21_dd`` and ``neural_dd`` against the posteriors under the 1D data-driven prior of
Section 5.1 instead. It writes ``delta_<name>.json`` per term and ``delta_cv.json`` (the scores) in the
format of the shipped ``ogm_ppl/fitted/`` (``ogm-ppl fit-prior deltas --out ogm_ppl/fitted``); read a term
back with ``delta_by_name(name, path=out_dir)`` or :func:`~ogm_ppl.models.delta.load_delta`.

:func:`~ogm_ppl.learn.fit_delta_setting` (:mod:`ogm_ppl.learn.delta_setting`) fits the same objective for
one's own sensor setting.

>>> from ogm_ppl.learn import fit_deltas
>>> len(FAMILIES), FAMILIES[:2], FAMILIES[-2:]
(29, ('borenstein_koren_opt', 'moravec_opt'), ('p21_dd', 'neural_dd'))
"""

from __future__ import annotations

import json
import os
import shlex
import time
from collections.abc import Callable, Sequence
from typing import Any

from ogm_ppl._dtype import float64
from ogm_ppl.learn._fit_common import FitOptionError, FitResult, check_float, check_int, check_out_dir

__all__ = [
    "DATASETS",
    "FAMILIES",
    "FOLDS",
    "REFERENCES",
    "SETTING",
    "cross_validation",
    "fit_deltas",
    "fit_families",
]

#: the 1D setting of the shipped terms (Section 2.5), in cells
SETTING: dict[str, Any] = {"F": 75, "wall": 60, "sigma": 3.0, "num_readings": (1, 10)}
#: the shipped terms' number of datasets and cross-validation folds
DATASETS, FOLDS = 1000, 10
#: L-BFGS settings of every fit
FIT: dict[str, Any] = {"max_iter": 500, "tol": 1e-10}
LITERATURE = (
    "borenstein_koren_opt",
    "moravec_opt",
    "marshall_barfoot_opt",
    "stachniss_opt",
    "elfes_opt",
    "neural_opt",
)
PN_MAX = 21
#: fitted against the posterior under the 1D data-driven prior (Section 5.1)
DATA_DRIVEN = ("p21_dd", "neural_dd")
#: the terms :func:`fit_deltas` fits, in the order it writes and scores them
FAMILIES: tuple[str, ...] = (*LITERATURE, *(f"p{n}" for n in range(1, PN_MAX + 1)), *DATA_DRIVEN)
#: shipped terms scored beside the fits (not fitted)
REFERENCES = ("haehnel", "moravec_thesis", "elfes_thesis", "p21_thesis")
#: the largest ``F`` (cells) and number of datasets accepted: the exact posteriors cost ~F^2 per dataset
MAX_F, MAX_DATASETS = 10_000, 1_000_000
_OPTIMIZER = "torch.optim.LBFGS(line_search_fn='strong_wolfe')"


def _makers() -> dict[str, Callable[[Any], Any]]:
    """Each Table 2.1 family and the network: ``name -> data -> fit result``, from the start values
    (Hähnel's ``log 4`` for the log-odds, Stachniss ``alpha = 3``, Elfes ``sigma = 3, l_min = -10``)."""
    from ogm_ppl.inference.variational.delta_fit import fit_delta
    from ogm_ppl.models.delta import BorensteinKoren, Elfes, MarshallBarfoot, Moravec, NeuralDelta, Stachniss

    def marshall_barfoot(data):
        best = None
        for beta in range(1, 6):  # l_occ for each integer beta, the best on the training data
            res = fit_delta(MarshallBarfoot(1.3863, beta), data, **FIT)
            if best is None or res.train_loss < best.train_loss:
                best = res
        return best

    return {
        "borenstein_koren_opt": lambda data: fit_delta(BorensteinKoren(1.3863), data, **FIT),
        "moravec_opt": lambda data: fit_delta(Moravec.haehnel(), data, **FIT),
        "marshall_barfoot_opt": marshall_barfoot,
        "stachniss_opt": lambda data: fit_delta(Stachniss(1.3863, -1.3863, 3.0), data, **FIT),
        "elfes_opt": lambda data: fit_delta(Elfes(3.0, -10.0, max_kappa=data.F), data, **FIT),
        "neural_opt": lambda data: fit_delta(NeuralDelta(data.F, hidden=16, seed=0), data, **FIT),
    }


def fit_families(data: Any, names: Sequence[str] = FAMILIES, *, pn_upto: int = 0) -> dict[str, Any]:
    """Fit the uniform-prior terms ``names`` (of :data:`FAMILIES`; the ``*_dd`` ones are skipped) on ``data``
    (:class:`~ogm_ppl.inference.variational.delta_fit.FitData`): ``name -> DeltaFitResult`` of
    :mod:`~ogm_ppl.inference.variational.delta_fit`, in :data:`FAMILIES` order. pN is fitted from p(N-1), so
    the chain p1 .. pM runs for the largest M named (or ``pn_upto``) and every link of it is returned."""
    from ogm_ppl.inference.variational.delta_fit import fit_delta, warm_start_pn

    makers = _makers()
    with float64():
        out = {name: makers[name](data) for name in LITERATURE if name in names}
        upto = max([pn_upto, *(int(n[1:]) for n in names if n in FAMILIES[len(LITERATURE) : -len(DATA_DRIVEN)])])
        prev = None
        for N in range(1, upto + 1):
            out[f"p{N}"] = res = fit_delta(warm_start_pn(prev, N), data, **FIT)
            prev = res.family
    return out


def _references(data: Any) -> dict[str, float]:
    import torch

    from ogm_ppl.inference.variational.delta_fit import cross_entropy_loss
    from ogm_ppl.models.delta import delta_by_name

    with torch.no_grad():
        return {n: float(cross_entropy_loss(delta_by_name(n), data)) for n in REFERENCES}


def cross_validation(data: Any, folds: int, names: Sequence[str] = FAMILIES, progress: Any = None) -> dict:
    """``folds``-fold cross-validation of the uniform-prior terms ``names`` and the :data:`REFERENCES`: fold
    ``k`` (datasets ``k s .. (k + 1) s - 1``, ``s = len(data) // folds``) is held out, the terms are fitted
    on the rest (:func:`fit_families`) and scored on it by the cross-entropy of the module docstring. Returns
    ``name -> {"mean", "std", "folds"}`` (population std over the folds), fits first then references."""
    import numpy as np
    import torch

    from ogm_ppl.inference.variational.delta_fit import cross_entropy_loss

    D = len(data)
    size = D // folds
    test: dict[str, list[float]] = {}
    for k in range(folds):
        te = torch.arange(k * size, (k + 1) * size)
        tr = torch.cat([torch.arange(0, k * size), torch.arange((k + 1) * size, D)])
        fits = fit_families(data.subset(tr), names)
        held = data.subset(te)
        with torch.no_grad():
            for name, res in fits.items():
                if name in names:
                    test.setdefault(name, []).append(float(cross_entropy_loss(res.family, held)))
        for name, v in _references(held).items():
            test.setdefault(name, []).append(v)
        if progress is not None:
            progress.update(note=f"fold {k + 1}")
    return {n: {"mean": float(np.mean(v)), "std": float(np.std(v)), "folds": v} for n, v in test.items()}


def _n_params(name: str, family: Any) -> int:
    """Free parameters: Marshall-Barfoot's ``l_occ`` and its chosen integer ``beta`` count as two."""
    return 2 if name == "marshall_barfoot_opt" else sum(p.numel() for p in family.parameters())


def fit_deltas(
    out_dir: str | os.PathLike,
    *,
    datasets: int = DATASETS,
    folds: int = FOLDS,
    families: Sequence[str] = FAMILIES,
    seed: int = 0,
    sigma: float = SETTING["sigma"],
    F: int = SETTING["F"],
    wall: int = SETTING["wall"],
    progress: bool = True,
) -> FitResult:
    """Fit the update terms ``families`` on ``datasets`` wall datasets, cross-validate them and write
    ``delta_<name>.json`` per term and ``delta_cv.json`` into ``out_dir`` (nothing else, each atomically,
    after every fit is done). The defaults remake the shipped ``ogm_ppl/fitted/delta_*.json``.

    Args:
        out_dir: the folder the files go to (created if missing).
        datasets: training datasets ``D`` (seeded by ``seed``; the ``*_dd`` terms' datasets are the same
            draws, scored under the data-driven prior).
        folds: cross-validation folds, 2..``datasets`` (0: none; ``heldout_cross_entropy`` is then null).
        families: names of :data:`FAMILIES` (pN fits the chain p1 .. pN first; ``p21_dd`` starts from p20).
        seed: the datasets' seed.
        sigma, F, wall: the sensor's noise, its range and the wall's cell (cells; default the shipped setting).
        progress: a line per fold on stderr.

    Returns:
        :class:`~ogm_ppl.learn.FitResult`: ``files``, the ``provenance`` written (the ``ogm-ppl fit-prior
        deltas`` command line), ``summary`` = the report (``settings``, ``folds``, ``cv`` with the per-fold
        scores, ``rows``: each term's parameter count, held-out mean and std and values, ``data_driven``
        scores, ``seconds``) and its table as ``markdown``.

    Raises:
        FitOptionError: an option out of range (the message names it and the limit), before any work.
    """
    out, D, K, names, sd, sg, FF, wl = _check_deltas(out_dir, datasets, folds, families, seed, sigma, F, wall)
    options = _options(
        [("datasets", D, DATASETS), ("folds", K, FOLDS), ("seed", sd, 0), ("sigma", sg, SETTING["sigma"])]
        + [("F", FF, SETTING["F"]), ("wall", wl, SETTING["wall"])]
    )
    if tuple(names) != FAMILIES:
        options += ["--families", *names]
    cmd = shlex.join(["ogm-ppl", "fit-prior", "deltas", "--out", str(out), *options])
    from ogm_ppl.datasets import wall_datasets
    from ogm_ppl.progress import Progress
    from ogm_ppl.provenance import provenance

    prov = {**provenance(cmd), "fitted_by": "ogm_ppl.learn.fit_deltas"}
    settings = {"num": D, "F": FF, "wall": wl, "sigma": sg, "num_readings": SETTING["num_readings"], "seed": sd}
    t0 = time.perf_counter()
    uniform = [n for n in names if n not in DATA_DRIVEN]
    with float64(), Progress(K + 1, "fit-prior deltas", unit="fit", enabled=progress) as bar:
        data = wall_datasets(**settings)
        data_dd = wall_datasets(**settings, prior="data_driven") if set(names) & set(DATA_DRIVEN) else None
        t_data = time.perf_counter() - t0
        t1 = time.perf_counter()
        cv = cross_validation(data, K, uniform, progress=bar) if K else {}
        t_cv = time.perf_counter() - t1
        full = fit_families(data, uniform, pn_upto=20 if "p21_dd" in names else 0)
        dd, dd_scores = _data_driven(names, full, data_dd)
        bar.update(note="all datasets")
    total = time.perf_counter() - t0
    rows = _rows(uniform, full, cv)
    report = {
        "settings": {**settings, "num_readings": list(settings["num_readings"])},
        "folds": K,
        "cv": cv,
        "rows": rows,
        "data_driven": dd_scores,
        "seconds": {"data": t_data, "cv": t_cv, "total": total},
    }
    text = _markdown(rows, dd_scores, D, K, t_data, t_cv, total)
    training = {
        **report["settings"],
        "prior": "uniform",
        "optimizer": _OPTIMIZER,
        **FIT,
        "function": "ogm_ppl.learn.fit_deltas",
    }
    from ogm_ppl.io import atomic_write_text
    from ogm_ppl.models.delta import family_to_dict

    fitted = {n: full[n] for n in uniform} | dd
    texts = {
        f"delta_{name}.json": {
            "format": 1,
            "name": name,
            "delta": family_to_dict(res.family),
            "training": {**training, "prior": "data_driven" if name.endswith("_dd") else "uniform"},
            "train_cross_entropy": res.train_loss,
            "heldout_cross_entropy": cv.get(name, {}).get("mean"),
            "provenance": prov,
        }
        for name, res in fitted.items()
    }
    texts["delta_cv.json"] = {
        "format": 1,
        "settings": report["settings"],
        "folds": K,
        "cv": {k: {"mean": v["mean"], "std": v["std"]} for k, v in cv.items()},
        "params": {r["name"]: r["params"] for r in rows},
        "data_driven": dd_scores,
        "provenance": prov,
    }
    files = tuple(atomic_write_text(out / f, json.dumps(rec, indent=1)) for f, rec in texts.items())
    return FitResult("deltas", files, prov, {**report, "markdown": text}, round(total, 2))


def _data_driven(names: Sequence[str], full: dict, data_dd: Any) -> tuple[dict, dict[str, float]]:
    """The ``*_dd`` terms named, fitted on ``data_dd``, and the cross-entropies on it of them and of their
    uniform-prior fits (where those were made)."""
    import torch

    from ogm_ppl.inference.variational.delta_fit import cross_entropy_loss, fit_delta, warm_start_pn
    from ogm_ppl.models.delta import NeuralDelta

    dd: dict[str, Any] = {}
    with float64():
        if "p21_dd" in names:
            dd["p21_dd"] = fit_delta(warm_start_pn(full["p20"].family, 21), data_dd, **FIT)
        if "neural_dd" in names:
            dd["neural_dd"] = fit_delta(NeuralDelta(data_dd.F, hidden=16, seed=0), data_dd, **FIT)
    if not dd:
        return dd, {}
    with torch.no_grad():
        scores = {n: float(cross_entropy_loss(r.family, data_dd)) for n, r in dd.items()}
        for name, word in (("p21", "p21"), ("neural_opt", "neural")):
            if name in full:
                scores[f"{word} (uniform-prior fit) on data-driven target"] = float(
                    cross_entropy_loss(full[name].family, data_dd)
                )
    return dd, scores


def _rows(uniform: Sequence[str], full: dict, cv: dict) -> list[dict]:
    """One row per fitted uniform-prior term and reference: parameter count, held-out score, values."""
    from ogm_ppl.models.delta import delta_by_name, family_to_dict

    rows = []
    for name in [*uniform, *REFERENCES]:
        fam = full[name].family if name in full else delta_by_name(name)
        score = cv.get(name, {})
        rows.append(
            {
                "name": name,
                "params": _n_params(name, fam),
                "test_mean": score.get("mean"),
                "test_std": score.get("std"),
                "values": family_to_dict(fam),
            }
        )
    return rows


def _markdown(rows: list[dict], dd_scores: dict, D: int, K: int, t_data: float, t_cv: float, total: float) -> str:
    """The report's table: each term, its parameter count, held-out score and (up to 21) fitted values."""
    md = [
        "| update term | parameters | held-out cross-entropy (mean +- sd over folds) | fitted values |",
        "|---|---|---|---|",
    ]
    for r in rows:
        vals = r["values"]["params"]
        if "net.0.weight" in vals:
            shown = f"MLP, hidden {r['values']['fixed']['hidden']}"
        else:
            flat = [x for v in vals.values() for x in (v if isinstance(v, list) else [v])]
            shown = ", ".join(f"{x:.4f}" for x in flat[:21])
            if "beta" in r["values"]["fixed"]:
                shown += f"; beta = {r['values']['fixed']['beta']}"
        score = "-" if r["test_mean"] is None else f"{r['test_mean']:.4f} +- {r['test_std']:.4f}"
        md.append(f"| {r['name']} | {r['params']} | {score} | {shown} |")
    times = f"data + exact posteriors {t_data:.1f} s, CV fits {t_cv:.1f} s, total {total:.1f} s."
    md += ["", f"{D} datasets, {K}-fold CV; {times}"]
    if dd_scores:
        md += [
            "",
            "Data-driven-prior target (mean summed cross-entropy over all datasets): "
            + "; ".join(f"{k} {v:.4f}" for k, v in dd_scores.items()),
        ]
    return "\n".join(md)


def _options(values: Sequence[tuple[str, Any, Any]]) -> list[str]:
    """``--name value`` for each value that is not its default (the recorded command line)."""
    return [x for name, v, default in values if v != default for x in (f"--{name}", f"{v:g}")]


def _check_deltas(out_dir, datasets, folds, families, seed, sigma, F, wall):
    """Every option of :func:`fit_deltas`, checked before any work."""
    out = check_out_dir(out_dir)
    D = check_int(datasets, "datasets", 2, MAX_DATASETS)
    K = check_int(folds, "folds", 0, D)
    if K == 1:
        raise FitOptionError("folds", f"must be 0 (no cross-validation) or between 2 and datasets ({D}), got 1")
    names = _check_names(families, FAMILIES)
    names = [n for n in FAMILIES if n in names]  # their order
    FF, sd = check_int(F, "F", 2, MAX_F), check_int(seed, "seed", 0)
    return out, D, K, names, sd, check_float(sigma, "sigma", 0.0), FF, check_int(wall, "wall", 1, FF - 1)


def _check_names(families: Any, known: Sequence[str] | None, option: str = "families") -> list[str]:
    """``families`` (one name or several) as a list of distinct known names (``known`` None: the names
    :func:`~ogm_ppl.inference.variational.fit_delta_for_setting` fits)."""
    names = [families] if isinstance(families, str) else list(families)
    if not names or not all(isinstance(n, str) for n in names):
        raise FitOptionError(option, f"give one or more names, got {families!r}")
    if known is None:
        from ogm_ppl.models.delta_setting import _check_name, setting_family_names

        for n in names:
            try:
                _check_name(n)
            except ValueError:
                raise FitOptionError(option, f"must name {setting_family_names()}; got {n!r}") from None
    else:
        bad = [n for n in names if n not in known]
        if bad:
            raise FitOptionError(option, f"must be among {', '.join(known)}; got {', '.join(map(repr, bad))}")
    return list(dict.fromkeys(names))
