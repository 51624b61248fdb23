r"""Update terms Delta fitted for one's own sensor setting (thesis Section 2.5), written with their provenance.

A term fitted to 1D data is a function of ``kappa - z`` in *cells*: right for the noise and range it was
fitted at (the shipped terms: ``sigma = 3``, ``F = 75``; :mod:`ogm_ppl.learn.deltas`) and wrong elsewhere
(:func:`~ogm_ppl.inference.variational.check_delta_setting` warns). :func:`fit_delta_setting` fits a term
at any ``(sigma, F)``: over ``num`` wall datasets ``z^(d)`` of that setting with exact posterior marginals
``p(m_k | z^(d))`` it minimises the mean summed cell cross-entropy

.. math:: \hat\theta = \arg\min_\theta \frac{1}{D}\sum_{d=1}^{D}\sum_{k=1}^{F}
          H\Bigl(p(m_k \mid z^{(d)}),\ \sigma\bigl(\textstyle\sum_n \Delta_\theta(k - z^{(d)}_n)\bigr)\Bigr)

(convex for the offset families it fits; :mod:`~ogm_ppl.inference.variational.setting_fit` explains why the
fit is cheap), then writes each term under the name
:func:`~ogm_ppl.inference.variational.setting_file_name` gives it, so that
``fit_delta_for_setting(..., cache_dir=out_dir)`` reuses it (``ogm-ppl fit-prior delta-setting``).

>>> from ogm_ppl.learn import fit_delta_setting
>>> r = fit_delta_setting(None, family="p3", sigma=2, F=20, num=4)
>>> sorted(r.summary["terms"]), r.files
(['p3'], ())
"""

from __future__ import annotations

import os
import shlex
import time
from collections.abc import Sequence
from pathlib import Path

from ogm_ppl.learn._fit_common import FitOptionError, FitResult, check_float, check_int, check_out_dir
from ogm_ppl.learn.deltas import DATASETS, MAX_DATASETS, MAX_F, SETTING, _check_names, _options

__all__ = ["MAX_READINGS", "fit_delta_setting"]

#: the most readings a dataset may draw
MAX_READINGS = 10_000


def fit_delta_setting(
    out_dir: str | os.PathLike | None,
    *,
    family: str | Sequence[str] = "p21",
    sigma: float,
    F: int,
    wall: int | None = None,
    num: int = DATASETS,
    num_readings: tuple[int, int] = SETTING["num_readings"],
    seed: int = 0,
    prior: str = "uniform",
    heldout: int = 0,
    reuse: bool = False,
) -> FitResult:
    """Fit the update term(s) ``family`` for one's own sensor setting and write each into ``out_dir``.

    Minimises the cross-entropy of the module docstring over ``num`` wall datasets of noise ``sigma`` and
    range ``F`` (cells: ``sigma_m / resolution``, ``max_range_m / resolution``; wall ``round(0.8 F)`` unless
    given), all names on one draw of the data
    (:func:`~ogm_ppl.inference.variational.fit_deltas_for_setting`, on the cells near the wall: the same
    optimum). Each term goes to ``out_dir / setting_file_name(name, sigma, F, ...)``
    (``delta_p21_sigma1_F400_wall320_n1000_r1-10_seed0_uniform.json``) with the ``training`` block
    :func:`~ogm_ppl.inference.variational.check_delta_setting` reads and the provenance (the ``ogm-ppl
    fit-prior delta-setting`` command line). Read it back with ``load_delta(path)``,
    ``load_setting_fit(path)`` or ``delta_by_name(stem, path=out_dir)`` (``stem``: the file name without
    ``delta_`` and ``.json``), or let ``fit_delta_for_setting(..., cache_dir=out_dir)`` find it.

    Args:
        out_dir: the folder the files go to (created if missing); ``None`` writes nothing.
        family: ``"pN"`` (N >= 1, e.g. ``"p21"``), ``"moravec_opt"``, ``"borenstein_koren_opt"``,
            ``"marshall_barfoot_opt"``, or several of them.
        sigma, F, wall: the sensor's noise, its range and the wall's cell, in cells.
        num, num_readings, seed, prior: the training datasets (``prior``: ``"uniform"`` or ``"data_driven"``).
        heldout: also score this many fresh datasets (seed ``seed + 1``) into ``heldout_cross_entropy``.
        reuse: a file of the same setting already in ``out_dir`` is read instead of refitted.

    Returns:
        :class:`~ogm_ppl.learn.FitResult`: ``files``, ``provenance``, ``summary["terms"][name]`` = the
        term's ``file`` (or None), ``stem``, ``delta`` (:func:`~ogm_ppl.models.delta.family_from_dict`
        rebuilds it), ``training``, ``train_cross_entropy`` and ``heldout_cross_entropy``.

    Raises:
        FitOptionError: an option out of range (the message names it and the limit), before any work.
    """
    out = None if out_dir is None else check_out_dir(out_dir)
    names = _check_names(family, None, "family")
    sg, FF = check_float(sigma, "sigma", 0.0), check_int(F, "F", 2, MAX_F)
    wl = check_int(round(0.8 * FF) if wall is None else wall, "wall", 1, FF - 1)
    n, sd = check_int(num, "num", 1, MAX_DATASETS), check_int(seed, "seed", 0)
    held = check_int(heldout, "heldout", 0, MAX_DATASETS)
    pair = () if isinstance(num_readings, (str, bytes)) else tuple(num_readings)
    if len(pair) != 2:
        raise FitOptionError("num_readings", f"must be two whole numbers LO HI, got {num_readings!r}")
    lo = check_int(pair[0], "num_readings", 1, MAX_READINGS)
    hi = check_int(pair[1], "num_readings", lo, MAX_READINGS)
    if prior not in ("uniform", "data_driven"):
        raise FitOptionError("prior", f"must be 'uniform' or 'data_driven', got {prior!r}")
    options = ["--family", *names, "--sigma", f"{sg:g}", "--F", str(FF)]
    options += _options([("wall", wl, round(0.8 * FF)), ("num", n, DATASETS), ("seed", sd, 0), ("heldout", held, 0)])
    options += [] if (lo, hi) == SETTING["num_readings"] else ["--num-readings", str(lo), str(hi)]
    options += ([] if prior == "uniform" else ["--prior", prior]) + (["--reuse"] if reuse else [])
    cmd = shlex.join(["ogm-ppl", "fit-prior", "delta-setting", *options, *([] if out is None else ["--out", str(out)])])
    from ogm_ppl.inference.variational.setting_fit import fit_deltas_for_setting, save_setting_fit, setting_file_name
    from ogm_ppl.models.delta import family_to_dict
    from ogm_ppl.provenance import provenance

    prov = {**provenance(cmd), "fitted_by": "ogm_ppl.learn.fit_delta_setting"}
    t0 = time.perf_counter()
    fits = fit_deltas_for_setting(
        names,
        sg,
        FF,
        wall=wl,
        num=n,
        num_readings=(lo, hi),
        seed=sd,
        prior=prior,
        heldout=held,
        cache_dir=out if reuse else None,
        provenance=prov,
    )
    terms, files = {}, []
    for name, (fam, training) in fits.items():
        file = setting_file_name(name, sg, FF, wall=wl, num=n, num_readings=(lo, hi), seed=sd, prior=prior)
        path = None if out is None else out / file
        if path is not None and not reuse:
            save_setting_fit(path, name, fam, training, provenance=prov)
        files += [] if path is None else [path]
        terms[name] = {
            "file": None if path is None else str(path),
            "stem": Path(file).stem[len("delta_") :],
            "delta": family_to_dict(fam),
            "training": training,
            "train_cross_entropy": training["train_cross_entropy"],
            "heldout_cross_entropy": training.get("heldout_cross_entropy"),
        }
    seconds = round(time.perf_counter() - t0, 2)
    return FitResult("delta-setting", tuple(files), prov, {"terms": terms}, seconds)
