r"""Update terms Delta fitted for a sensor setting, and a warning when a term is used outside its own
(Section 2.5).

Section 2.5 fits Delta by minimising the summed cell cross-entropy against exact 1D posteriors,

.. math:: \hat\theta = \arg\min_\theta \frac{1}{D}\sum_{d=1}^{D}\sum_{k=1}^{F}
          H\bigl(p(m_k \mid z^{(d)}),\ \sigma(\textstyle\sum_n \Delta_\theta(k - z^{(d)}_n))\bigr),

on datasets of a stationary robot, a wall at ``f`` and Gaussian readings ``N(f, sigma^2)``: the thesis
(and the shipped ``ogm_ppl/fitted/delta_*.json``) at ``F = 75``, ``f = 60``, ``sigma = 3`` cells. A term
fitted there is a function of ``kappa - z`` in *cells*, so it is only right for that sigma in cells: at
5 cm cells a laser's noise is ~1 cell, its range 400 cells. :func:`fit_delta_for_setting` fits the
named family at any ``(sigma, F)`` (wall ``round(0.8 F)`` unless given) on
:func:`~ogm_ppl.inference.variational.wall_data.wall_datasets`; :func:`check_delta_setting` warns
(:class:`FittedSettingWarning`) when a term is used outside the setting it was fitted for.

Two facts make the fit cheap (the exact posteriors, ~5-8 ms per dataset, are the dominant cost):

* **Convexity.** For the offset families fitted here (pN, Moravec, Borenstein-Koren, Marshall-Barfoot
  at fixed ``beta``) the logits are linear in the parameters and the cross-entropy is convex in the
  logits, so the objective is convex: its minimum does not depend on the start. pN starts at 0 (the
  p1 -> p21 warm-start chain of :func:`ogm_ppl.learn.fit_deltas` reaches the same p21; measured at the shipped
  setting it gives the same values to 1e-6 and starting at the shipped p21 is *slower*, 2.6 s against
  0.4 s, L-BFGS's line search idling at an optimum). Parameters that act only on cells whose exact
  posterior is ~0 (e.g. the far-before values of pN at sigma = 1, log-odds below -16) are weakly
  determined: the loss is flat there to 1e-6, compare fits by the loss, not those values.
* **Only cells near the wall carry parameters' differences** (:func:`reduce_fit_data`). For an offset
  family with ``Delta(d) = Delta_far`` for ``d <= L`` and ``Delta(d) = 0`` for ``d > H``, every cell
  ``k <= z_lo + L`` (``z_lo``: the least reading of all datasets) has the logit
  ``l_before = (n_hits + n_max) Delta_far`` and every cell ``k > z_hi + H`` has ``l_after = n_max Delta_far``.
  Their cross-entropies sum exactly to ``S softplus(-l) + (C - S) softplus(l)`` with ``C`` the number of
  such cells and ``S`` the sum of their exact marginals. The loss over ``F`` cells becomes one over the
  ``(z_hi - z_lo) + (H - L)`` cells near the wall plus two aggregated cells: the *same* loss (an identity,
  checked against the full loss at the end of every fit). At ``F = 400``, 1000 datasets: ~40 cells
  instead of 400; one loss and gradient 2-4 ms instead of 57-85 ms; the p21 fit ~1 s instead of 7-9 s
  (measured on one thread; the fit runs torch on one thread, faster for matrices this small).
"""

from __future__ import annotations

import math
import numbers
import time
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from functools import partial
from pathlib import Path

import torch
from torch import nn

from ogm_ppl.inference.variational.delta_fit import DeltaFitResult, FitData, cross_entropy_loss, minimise
from ogm_ppl.inference.variational.wall_data import wall_datasets
from ogm_ppl.models.delta import (
    PN,
    BorensteinKoren,
    DeltaFamily,
    DeltaFileError,
    MarshallBarfoot,
    Moravec,
    family_to_dict,
    load_delta,
)
from ogm_ppl.models.delta_setting import (  # noqa: F401  (re-exported)
    _OPT,
    F_FACTOR,
    SIGMA_TOLERANCE,
    FittedSettingWarning,
    _check_name,
    check_delta_setting,
    fit_family_for,
    setting_family_names,
)

__all__ = [
    "fit_delta_for_setting",
    "fit_family_for",
    "fit_deltas_for_setting",
    "fit_on_data",
    "check_delta_setting",
    "FittedSettingWarning",
    "save_setting_fit",
    "load_setting_fit",
    "setting_file_name",
    "setting_family_names",
    "reduce_fit_data",
    "reduced_cross_entropy_loss",
    "ReducedFitData",
    "SIGMA_TOLERANCE",
    "F_FACTOR",
]


_FUNCTION = "ogm_ppl.inference.variational.fit_delta_for_setting"


def _starts(name: str) -> list[DeltaFamily]:
    """Start points: one family, or Marshall-Barfoot at each integer beta 1..5 (the best one wins)."""
    _check_name(name)
    if name.startswith("p") and name[1:].isdigit():
        return [PN.zeros(int(name[1:]))]
    if name == "moravec_opt":
        return [Moravec.haehnel()]
    if name == "borenstein_koren_opt":
        return [BorensteinKoren(1.3863)]
    return [MarshallBarfoot(1.3863, beta) for beta in range(1, 6)]


def _offset_bounds(family: DeltaFamily) -> tuple[int, int] | None:
    """``(L, H)`` with ``Delta(d) = far()`` for ``d <= L`` and ``Delta(d) = 0`` for ``d > H``, or ``None``."""
    if type(family) is PN:
        return family.lo, family.lo + family.N - 1
    if type(family) in (Moravec, BorensteinKoren):
        return -1, 0
    if type(family) is MarshallBarfoot:
        return -1, family.beta - 1
    return None


@dataclass(frozen=True)
class ReducedFitData:
    """Fit data cut to the cells near the wall (:func:`reduce_fit_data`); ``D`` datasets.

    ``hits``: ``D x Z`` counts of readings ``z = zlo .. zlo + Z - 1``; ``n_max``: ``D`` max-range counts;
    ``exact``: ``D x W`` exact marginals of cells ``a .. a + W - 1``; ``before_mass`` / ``after_mass``: ``D``
    sums of the exact marginals of cells ``1 .. a - 1`` (``n_before`` cells) and ``a + W .. F``
    (``n_after`` cells).
    """

    hits: torch.Tensor
    n_max: torch.Tensor
    exact: torch.Tensor
    before_mass: torch.Tensor
    after_mass: torch.Tensor
    n_before: int
    n_after: int
    zlo: int
    a: int
    F: int


def reduce_fit_data(data: FitData, left: int, right: int) -> ReducedFitData | None:
    """Cut ``data`` to the cells that an offset family with bounds ``(left, right)`` = ``(L, H)`` treats
    differently (module docstring): window ``a = max(1, z_lo + L + 1) .. b = min(F, z_hi + H)``, the cells
    before and after it aggregated. ``None`` when no dataset has a hit reading (nothing to cut around).
    """
    F = int(data.F)
    hits_all = data.counts[:, : F + 1]
    seen = torch.nonzero(hits_all.sum(0) > 0).flatten()
    if seen.numel() == 0:
        return None
    zlo, zhi = int(seen[0]), int(seen[-1])
    a = max(1, min(zlo + left + 1, F))
    b = max(a, min(F, zhi + right))
    exact = data.exact
    return ReducedFitData(
        hits=hits_all[:, zlo : zhi + 1],
        n_max=data.counts[:, F + 1],
        exact=exact[:, a : b + 1],
        before_mass=exact[:, 1:a].sum(1),
        after_mass=exact[:, b + 1 : F + 1].sum(1),
        n_before=a - 1,
        n_after=F - b,
        zlo=zlo,
        a=a,
        F=F,
    )


def _ce(p: torch.Tensor, lg: torch.Tensor, n: float | torch.Tensor = 1.0) -> torch.Tensor:
    """``n`` cells of logit ``lg`` whose exact marginals sum to ``p``: ``p softplus(-l) + (n - p) softplus(l)``."""
    return p * nn.functional.softplus(-lg) + (n - p) * nn.functional.softplus(lg)


def reduced_cross_entropy_loss(family: DeltaFamily, r: ReducedFitData) -> torch.Tensor:
    """:func:`~ogm_ppl.inference.variational.delta_fit.cross_entropy_loss` on reduced data (the same value
    for the family the data was reduced for): window cells by ``hits @ Delta(k - z)^T``, plus the two
    aggregated cells."""
    W, Z = r.exact.shape[1], r.hits.shape[1]
    k = torch.arange(r.a, r.a + W, dtype=torch.float64)
    z = torch.arange(r.zlo, r.zlo + Z, dtype=torch.float64)
    far = family.far()
    lw = r.hits @ family.delta(k[:, None] - z[None, :]).T + r.n_max[:, None] * far
    before = _ce(r.before_mass, (r.hits.sum(1) + r.n_max) * far, r.n_before)
    after = _ce(r.after_mass, r.n_max * far, r.n_after)
    return (_ce(r.exact, lw).sum(1) + before + after).mean()


def fit_on_data(
    name: str, data: FitData, *, reduce: bool = True, max_iter: int = 500, tol: float = 1e-10
) -> DeltaFitResult:
    """Fit the family ``name`` (:func:`setting_family_names`) on ``data`` by L-BFGS (Section 2.5).

    ``reduce``: minimise the reduced loss (:func:`reduce_fit_data`); the full loss is evaluated at the end
    and must agree to 1e-9 (relative) or a ``RuntimeError`` is raised. ``train_loss`` is the full loss.
    Marshall-Barfoot: ``l_occ`` at each ``beta`` in 1..5, the best on ``data``.
    """
    best: DeltaFitResult | None = None
    with _one_thread():
        for family in _starts(name):
            best = _fit_one(name, family, data, best, reduce=reduce, max_iter=max_iter, tol=tol)
    assert best is not None
    return best


@contextmanager
def _one_thread() -> Iterator[None]:
    """torch on one intra-op thread, restored after: the fit's matrices are small (``D x ~40``), and on a
    busy 2-core machine two threads made each evaluation ~7 times slower (measured)."""
    old = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        yield
    finally:
        torch.set_num_threads(old)


def _fit_one(
    name: str,
    family: DeltaFamily,
    data: FitData,
    best: DeltaFitResult | None,
    *,
    reduce: bool,
    max_iter: int,
    tol: float,
) -> DeltaFitResult:
    """One start point fitted; the better of it and ``best``."""
    bounds = _offset_bounds(family) if reduce else None
    r = reduce_fit_data(data, *bounds) if bounds is not None else None
    if r is None:
        res = minimise(family, partial(cross_entropy_loss, family, data), max_iter=max_iter, tol=tol)
    else:
        res = minimise(family, partial(reduced_cross_entropy_loss, family, r), max_iter=max_iter, tol=tol)
        with torch.no_grad():
            full = float(cross_entropy_loss(family, data))
        if not abs(full - res.train_loss) <= 1e-9 * max(1.0, abs(full)):
            raise RuntimeError(
                f"reduced loss {res.train_loss!r} != full loss {full!r} for {name}: "
                "the reduction does not hold for this family"
            )
        res = DeltaFitResult(family, full, res.iterations)
    return res if best is None or res.train_loss < best.train_loss else best


def _is_int(x: object) -> bool:
    return isinstance(x, numbers.Integral) and not isinstance(x, bool)


def _check_setting(sigma: float, F: int, wall: int, num: int, num_readings: tuple[int, int]) -> None:
    if not (isinstance(sigma, (int, float)) and math.isfinite(sigma) and sigma > 0):
        raise ValueError(f"sigma must be a positive number of cells, got {sigma!r}")
    if not _is_int(F) or F < 2:
        raise ValueError(f"F must be an integer number of cells >= 2, got {F!r}")
    if not _is_int(wall) or not 1 <= wall < F:
        raise ValueError(f"wall must be an integer in 1..F-1 = 1..{F - 1}, got {wall!r}")
    if not _is_int(num) or num < 1:
        raise ValueError(f"num must be a positive integer, got {num!r}")
    lo, hi = num_readings
    if not 1 <= lo <= hi:
        raise ValueError(f"num_readings must be (lo, hi) with 1 <= lo <= hi, got {num_readings!r}")


def setting_file_name(
    name: str,
    sigma: float,
    F: int,
    *,
    wall: int | None = None,
    num: int = 1000,
    num_readings: tuple[int, int] = (1, 10),
    seed: int = 0,
    prior: str = "uniform",
) -> str:
    """The cache file name of a setting fit, e.g. ``delta_p21_sigma1_F400_wall320_n1000_r1-10_seed0_uniform.json``."""
    wall = round(0.8 * F) if wall is None else wall
    lo, hi = num_readings
    return f"delta_{name}_sigma{float(sigma):g}_F{F}_wall{wall}_n{num}_r{lo}-{hi}_seed{seed}_{prior}.json"


def fit_delta_for_setting(
    name: str,
    sigma: float,
    F: int,
    *,
    wall: int | None = None,
    num: int = 1000,
    num_readings: tuple[int, int] = (1, 10),
    seed: int = 0,
    prior: str = "uniform",
    heldout: int = 0,
    reduce: bool = True,
    max_iter: int = 500,
    tol: float = 1e-10,
    cache_dir: str | Path | None = None,
) -> tuple[DeltaFamily, dict]:
    r"""Fit the update term ``name`` for a stationary 1D sensor of noise ``sigma`` and range ``F`` (cells).

    Minimises the mean summed cell cross-entropy ``H(p_exact, q_Delta)`` of Section 2.5 over
    ``wall_datasets(num, F, wall, sigma, num_readings, prior, seed)`` (exact 1D posteriors; wall
    ``round(0.8 F)`` unless given, the thesis's 60 of 75). ``name``: ``"pN"`` (e.g. ``"p21"``),
    ``"moravec_opt"`` (Moravec/Hähnel's two-value term), ``"borenstein_koren_opt"``,
    ``"marshall_barfoot_opt"``. ``heldout > 0``: also score ``heldout`` fresh datasets (seed ``seed + 1``).
    ``reduce``: fit on the cells near the wall (:func:`reduce_fit_data`; the same optimum).

    Returns ``(family, training)``: the fitted term (its ``fitted_setting`` set, so
    :func:`check_delta_setting` knows it) and the ``training`` block of its artefact: the settings above,
    ``optimizer``, ``max_iter``, ``tol``, ``reduced``, ``function``, ``train_cross_entropy`` and
    ``heldout_cross_entropy`` (``None`` unless ``heldout``; nats per dataset, summed over cells 1..F) and
    ``seconds`` (``data``, ``fit``: informational).

    ``cache_dir``: read the fit from ``cache_dir / setting_file_name(...)`` if that file exists (validated by
    :func:`load_setting_fit`; its setting must be the one asked for, else :class:`DeltaFileError`), else
    fit and write it there. Cost (measured on 2 busy cores, ``num = 1000``): data ~5-9 ms per dataset
    (7-9 s at ``F = 400``), the fit 0.1-5 s. :func:`fit_deltas_for_setting` fits several names on one data.
    """
    return fit_deltas_for_setting(
        [name],
        sigma,
        F,
        wall=wall,
        num=num,
        num_readings=num_readings,
        seed=seed,
        prior=prior,
        heldout=heldout,
        reduce=reduce,
        max_iter=max_iter,
        tol=tol,
        cache_dir=cache_dir,
    )[name]


def fit_deltas_for_setting(
    names: Sequence[str],
    sigma: float,
    F: int,
    *,
    wall: int | None = None,
    num: int = 1000,
    num_readings: tuple[int, int] = (1, 10),
    seed: int = 0,
    prior: str = "uniform",
    heldout: int = 0,
    reduce: bool = True,
    max_iter: int = 500,
    tol: float = 1e-10,
    cache_dir: str | Path | None = None,
    provenance: dict | None = None,
) -> dict[str, tuple[DeltaFamily, dict]]:
    """:func:`fit_delta_for_setting` for several names on one draw of the data: ``name -> (family, training)``.
    ``provenance``: recorded in the files written into ``cache_dir`` (:func:`save_setting_fit`)."""
    for name in names:
        _check_name(name)
    if wall is None and _is_int(F):
        wall = round(0.8 * F)
    _check_setting(sigma, F, wall, num, num_readings)  # type: ignore[arg-type]
    F, wall, num, seed = int(F), int(wall), int(num), int(seed)  # type: ignore[arg-type]
    setting = {
        "num": num,
        "F": F,
        "wall": wall,
        "sigma": float(sigma),
        "num_readings": list(num_readings),
        "seed": seed,
        "prior": prior,
    }
    out: dict[str, tuple[DeltaFamily, dict]] = {}
    paths: dict[str, Path] = {}
    for name in names if cache_dir is not None else ():
        paths[name] = path = Path(str(cache_dir)) / setting_file_name(
            name, sigma, F, wall=wall, num=num, num_readings=num_readings, seed=seed, prior=prior
        )
        if path.exists():
            family, training = load_setting_fit(path)
            differs = {k: (training.get(k), v) for k, v in setting.items() if training.get(k) != v}
            if differs:
                raise DeltaFileError(
                    f"{path}: its training setting differs from the one asked for "
                    f"(file, asked): {differs}; delete the file to refit"
                )
            out[name] = family, training
    todo = [n for n in names if n not in out]
    if not todo:
        return out
    t0 = time.perf_counter()
    data = wall_datasets(num=num, F=F, wall=wall, sigma=sigma, num_readings=num_readings, prior=prior, seed=seed)
    test = None
    if heldout > 0:
        test = wall_datasets(
            num=heldout, F=F, wall=wall, sigma=sigma, num_readings=num_readings, prior=prior, seed=seed + 1
        )
    t_data = time.perf_counter() - t0
    for name in todo:
        t1 = time.perf_counter()
        res = fit_on_data(name, data, reduce=reduce, max_iter=max_iter, tol=tol)
        t_fit = time.perf_counter() - t1
        held = None
        if test is not None:
            with torch.no_grad():
                held = float(cross_entropy_loss(res.family, test))
        training = {
            **setting,
            "optimizer": "torch.optim.LBFGS(line_search_fn='strong_wolfe')",
            "max_iter": max_iter,
            "tol": tol,
            "reduced": bool(reduce),
            "function": _FUNCTION,
            "train_cross_entropy": res.train_loss,
            "heldout": heldout,
            "heldout_cross_entropy": held,
            "seconds": {"data": t_data, "fit": t_fit},
        }
        res.family.fitted_setting = {**training, "name": name}
        if name in paths:
            save_setting_fit(paths[name], name, res.family, training, provenance=provenance)
        out[name] = res.family, training
    return {n: out[n] for n in names}


def save_setting_fit(
    path: str | Path, name: str, family: DeltaFamily, training: dict, *, provenance: dict | None = None
) -> Path:
    """Write a fitted term as a Delta artefact (the format of ``ogm_ppl/fitted/delta_*.json``: ``format``,
    ``name``, ``delta``, ``training``, ``train_cross_entropy``, ``heldout_cross_entropy``, and ``provenance``
    when given); atomic."""
    import json

    from ogm_ppl.io import atomic_write_text

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    record = {
        "format": 1,
        "name": name,
        "delta": family_to_dict(family),
        "training": training,
        "train_cross_entropy": training.get("train_cross_entropy"),
        "heldout_cross_entropy": training.get("heldout_cross_entropy"),
        **({} if provenance is None else {"provenance": provenance}),
    }
    atomic_write_text(path, json.dumps(record, indent=1))
    return path


_REQUIRED = {
    "sigma": "a positive number",
    "F": "an integer >= 2",
    "wall": "an integer in 1..F-1",
    "num": "a positive integer",
    "seed": "an integer",
    "num_readings": "a list [lo, hi]",
    "prior": "a string",
}


def load_setting_fit(path: str | Path) -> tuple[DeltaFamily, dict]:
    """Read a setting fit written by :func:`save_setting_fit` (or a shipped artefact): ``(family, training)``.

    The term is validated by :func:`~ogm_ppl.models.delta.load_delta` (format, family, parameter shapes,
    finite values) and its ``training`` block here (``sigma``, ``F``, ``wall``, ``num``, ``seed``,
    ``num_readings``, ``prior``); :class:`~ogm_ppl.models.DeltaFileError` names the path and what is wrong.
    """
    family = load_delta(path)  # DeltaFileError names the path
    training = family.fitted_setting
    if training is None:
        raise DeltaFileError(f"{path}: no 'training' block: not a fitted term (needs {sorted(_REQUIRED)})")
    training = {k: v for k, v in training.items() if k != "name"}
    missing = [k for k in _REQUIRED if k not in training]
    if missing:
        raise DeltaFileError(f"{path}: 'training' lacks {missing}")
    try:
        nr = training["num_readings"]
        if not (isinstance(nr, list) and len(nr) == 2 and all(isinstance(x, int) for x in nr)):
            raise ValueError(f"'num_readings' must be {_REQUIRED['num_readings']} of integers, got {nr!r}")
        if not isinstance(training["prior"], str):
            raise ValueError(f"'prior' must be a string, got {training['prior']!r}")
        if not _is_int(training["seed"]):
            raise ValueError(f"'seed' must be an integer, got {training['seed']!r}")
        _check_setting(training["sigma"], training["F"], training["wall"], training["num"], tuple(nr))
    except ValueError as e:
        raise DeltaFileError(f"{path}: bad 'training' block: {e}") from None
    return family, training
