"""Parameters shared by the methods that work on the occupancy model (prior and sensor)."""

from __future__ import annotations

from dataclasses import dataclass

from ogm_ppl.methods.params import Float, Optional, ParamError, PriorName, param
from ogm_ppl.methods.problem import MapProblem

__all__ = ["ModelParams", "patch_arg"]


@dataclass(frozen=True)
class ModelParams:
    """The model ``p(m) p(z | m)``: a prior by name and ``GaussianRange(sigma_cells)``."""

    prior: str = param(
        "independent",
        PriorName(),
        "map prior (prior_by_name: independent, mrf:houseexpo, border:houseexpo, ...)",
    )
    lam: float | None = param(
        None,
        Optional(Float(0, 1, lo_open=True, hi_open=True)),
        "cell occupancy of the prior 'independent' (default 0.5)",
    )
    sigma_cells: float | None = param(
        None,
        Optional(Float(0, lo_open=True)),
        "range noise of the sensor model in cells (default: the data's)",
    )

    def check(self) -> None:
        if self.lam is not None and self.prior != "independent":
            raise ParamError("lam", f"applies to the prior 'independent' only, not to {self.prior!r}")

    def model(self, problem: MapProblem, p_rand: float = 0.0):
        return problem.model(self.prior, self.lam, self.sigma_cells, p_rand)

    def model_details(self, problem: MapProblem) -> dict:
        return {"sigma_cells": problem.sigma(self.sigma_cells), "ray_cells": int(problem.rays.nnz)}


def patch_arg(patch):
    """A patch parameter as the kernels take it (``[h, w]`` -> ``(h, w)``)."""
    return tuple(patch) if isinstance(patch, list) else patch
