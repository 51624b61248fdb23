r"""``ogm``: log-odds occupancy grid mapping with any update term Delta (Section 2.4, Eq. 2.10).

``l_k = l_0 + sum_{n: k on ray n} (Delta(kappa_nk, z_n) - l_0)``, ``p_k = sigmoid(l_k)``; the traversal and
the update fused in one pass (:func:`~ogm_ppl.inference.log_odds.evidence_grid_from_scans`). The term is
used as shipped (a fitted term used outside the sensor setting it was fitted for warns, and the warning
is kept in the details) or refitted for the data's setting (``fit = "setting"``, Section 2.5).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

from ogm_ppl.methods.params import Choice, DeltaName, Float, Int, Optional, Pair, ParamError, param
from ogm_ppl.methods.problem import MapProblem, MapResult, RunContext
from ogm_ppl.methods.registry import register_method

__all__ = ["OGMParams", "ogm"]


@dataclass(frozen=True)
class OGMParams:
    delta: str = param("haehnel", DeltaName(), "the update term (delta_by_name: haehnel, p21, elfes_thesis, ...)")
    prior: float = param(0.5, Float(0, 1, lo_open=True), "prior occupancy l_0 = logit(prior) of every cell")
    clamp: object = param(None, Optional(Pair("log-odds")), "clamp the log-odds to [lo, hi] after each update")
    fit: str = param("none", Choice("none", "setting"), "'setting': refit the term for the data's sigma and range")
    sigma_cells: float | None = param(
        None,
        Optional(Float(0, lo_open=True)),
        "the sensor setting's range noise in cells (default: the data's)",
    )
    threads: int | None = param(
        None,
        Optional(Int(lo=1)),
        "walk the rays on this many of numba's threads (default all; the same map to the last bit for any number: "
        "fixed-point sums); a clamped map is one thread's",
    )

    def check(self) -> None:
        if self.threads is not None:
            from ogm_ppl.inference.mcmc.parallel import max_threads

            if self.threads > 1 and self.clamp is not None:
                raise ParamError("threads", "a clamped map adds its terms in reading order, on one thread")
            if self.threads > max_threads():
                raise ParamError("threads", f"at most numba's {max_threads()} threads (NUMBA_NUM_THREADS)")
        if self.fit == "setting":
            from ogm_ppl.inference.variational.setting_fit import (
                fit_family_for,
                setting_family_names,
            )

            if fit_family_for(self.delta) is None:
                raise ParamError(
                    "fit",
                    f"cannot refit {self.delta!r} for a sensor setting; fittable: {setting_family_names()}",
                )


def _delta(params: OGMParams, problem: MapProblem, ctx: RunContext):
    """The update term and what to record about its sensor setting (the data's ``sigma_cells`` or the
    method's, and the maximum range in cells); no setting check when the noise is unknown."""
    from ogm_ppl.inference.variational import (
        check_delta_setting,
        fit_delta_for_setting,
        fit_family_for,
    )
    from ogm_ppl.models import delta_by_name

    known = params.sigma_cells is not None or problem.sigma_cells is not None
    sigma, F = problem.sigma(params.sigma_cells), problem.max_range_cells
    setting = {"sigma_cells": sigma, "F_cells": F}
    if params.fit == "setting":
        family = fit_family_for(params.delta)
        assert family is not None  # OGMParams.check refuses terms it cannot refit
        cache = None if ctx.cache_dir is None else ctx.cache_dir / "deltas"
        delta, training = fit_delta_for_setting(family[0], sigma, F, prior=family[1], cache_dir=cache)
        keep = ("F", "wall", "sigma", "num", "prior", "train_cross_entropy")
        return delta, {"delta_setting": setting, "delta_fitted": {k: training.get(k) for k in keep}}
    delta = delta_by_name(params.delta)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        # the noise of a real log is not known: the range alone is checked
        check_delta_setting(delta, sigma if known else None, F, where=ctx.where or "this map", fit_sigma=sigma)
    for w in caught:
        warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
    checked = setting if known else {"F_cells": F}
    return delta, {"delta_setting": checked, "warnings": [str(w.message) for w in caught]}


def _clamp(clamp) -> tuple[float, float] | None:
    return None if clamp is None else (float(clamp[0]), float(clamp[1]))


@register_method("ogm", OGMParams, aliases={"p21": {"delta": "p21"}, "elfes": {"delta": "elfes_thesis"}})
def ogm(params: OGMParams, problem: MapProblem, ctx: RunContext) -> MapResult:
    """Log-odds occupancy grid mapping with an update term Delta (traditional OGM: haehnel; Section 2.4)."""
    from ogm_ppl.inference.log_odds import evidence_grid_from_scans

    delta, details = _delta(params, problem, ctx)
    ev = evidence_grid_from_scans(
        problem.grid,
        problem.scans,
        delta,
        prior=params.prior,
        clamp=_clamp(params.clamp),
        check_setting=False,  # _delta checked it, with the noise where it is known
        threads=params.threads,
    )
    details = {"ray_cast": "fused with the update (evidence_grid_from_scans)", **details}
    return MapResult(ev.probabilities.numpy(), ev.observed.numpy(), details)
