"""Parameters shared by the methods that work on the occupancy model (prior and sensor)."""

from __future__ import annotations

from dataclasses import dataclass

from ogm_ppl.methods.params import Float, Optional, ParamError, PriorName, SensorName, param
from ogm_ppl.methods.problem import MapProblem

__all__ = ["ModelParams", "patch_arg"]


@dataclass(frozen=True)
class ModelParams:
    """The model ``p(m) p(z | m)``: a prior by name and a sensor by name
    (:func:`~ogm_ppl.sensors.sensor_by_name`: ``gaussian`` is ``GaussianRange(sigma_cells, p_rand)``)."""

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
    sensor: str = param(
        "gaussian",
        SensorName(),
        "forward sensor model (sensor_by_name: gaussian, or a kind registered with register_sensor; "
        "KIND:KEY=VALUE,... sets its options)",
    )
    p_rand: float = param(
        0.0, Float(0, 1, hi_open=True), "sensor model's share of random readings (0: the thesis's model)"
    )

    def check(self) -> None:
        if self.lam is not None and self.prior != "independent":
            raise ParamError("lam", f"applies to the prior 'independent' only, not to {self.prior!r}")

    def model(self, problem: MapProblem):
        """The :class:`~ogm_ppl.models.OccupancyModel` of ``problem`` under these parameters."""
        return problem.model(self.prior, self.lam, self.sigma_cells, self.p_rand, self.sensor)

    def model_details(self, problem: MapProblem, model) -> dict:
        """What to record of ``model`` (:meth:`model` of ``problem``): its range noise, its sensor, the rays'
        cells."""
        return {
            "sigma_cells": problem.sigma(self.sigma_cells),
            "sensor_model": repr(model.sensor),
            "ray_cells": int(problem.rays.nnz),
        }


def patch_arg(patch):
    """A patch parameter as the kernels take it (``[h, w]`` -> ``(h, w)``)."""
    return tuple(patch) if isinstance(patch, list) else patch


#: the most patch configurations a patch method may enumerate in one run (``patches x 2^L x passes``);
#: at the tens of nanoseconds one configuration costs, 2^33 is several minutes
MAX_PATCH_CONFIGURATIONS = 1 << 33


def check_patch_work(patch, ndim: int, num_cells: int, passes: int, overlap: bool, what: str) -> None:
    """Refuse a patch run that would enumerate more than :data:`MAX_PATCH_CONFIGURATIONS` configurations.

    Every patch update enumerates all ``2^L`` configurations of its ``L`` cells (Sections 3.2, 4.3), so a
    run costs ``patches x 2^L x passes`` of them (``patches``: ``K`` centred on every cell with ``overlap``,
    else the ``K / L`` tiles). Raises :class:`ParamError` on ``patch``
    naming the count and the limit (as brute force names ``max_cells``)."""
    from ogm_ppl.inference.tiling import patch_shape

    dr, _ = patch_shape(patch_arg(patch), ndim, max_cells=64)
    L = len(dr)
    num_patches_per_pass = num_cells if overlap else -(-num_cells // L)
    work = float(num_patches_per_pass) * float(2**L) * int(passes)
    if work > MAX_PATCH_CONFIGURATIONS:
        raise ParamError(
            "patch",
            f"{what} with {L}-cell patches enumerates {num_patches_per_pass:,.0f} x 2^{L} x {passes} = {work:.3g} "
            f"configurations, over the limit of 2^33 = {MAX_PATCH_CONFIGURATIONS:.3g} "
            f"(ogm_ppl.methods._model.MAX_PATCH_CONFIGURATIONS, hours of work); use a smaller patch, fewer sweeps "
            f"or a smaller map",
        )
