r"""The compiled face of a sensor: one bundle per reading kind, and each kind's compiled reading model.

The exploration kernels (:mod:`ogm_ppl.exploration.information`) sum and sample over a sensor's readings
inside numba loops, so they never call a sensor's Python ``log_prob``. A sensor that wants them returns a
bundle from :meth:`SensorModel.compiled(bin_width) <ogm_ppl.sensors.SensorModel.compiled>` (``None``, the
default: no compiled reading model, and the information gain refuses the sensor naming what to implement).
The kinds the library ships:

* :class:`GaussianReading` ``(sigma, p_rand, width)`` — :class:`~ogm_ppl.sensors.GaussianRange`, its ranges
  in bins of ``width`` cells, :mod:`~ogm_ppl.sensors_compiled.gaussian`;
* :class:`PatternReading` ``(p_occ)`` — :class:`~ogm_ppl.sensors.PatternMatch`,
  :mod:`~ogm_ppl.sensors_compiled.pattern`.

The kernels call the generic entry points of :mod:`~ogm_ppl.sensors_compiled.registry` (``num_outcomes``,
``bin_prob``, ``fill_row``, ``log_reading``, ``coord``, ``draw``), which numba resolves to the registered
functions of the bundle's type when it compiles a kernel for that type: one specialised loop per kind, with no
branch on the kind anywhere. This package imports numpy and numba only (and nothing else of the library).

**A sensor of your own** explores once it has a compiled face, in one module: a ``typing.NamedTuple`` bundle
of its parameters (numbers or arrays; numba takes it as one argument), its reading model as numba functions
(``@numba.njit(inline="always")``, or plain functions numba compiles inline) with the signatures of
:mod:`~ogm_ppl.sensors_compiled.registry`, and one :func:`register` call, run when the module is imported::

    class LaplaceReading(NamedTuple):
        scale: float
        width: float

    register(LaplaceReading, num_outcomes=..., bin_prob=..., log_reading=..., coord=..., draw=...,
             continuous=True)

Its :class:`~ogm_ppl.sensors.SensorModel` then returns ``LaplaceReading(...)`` from ``compiled(bin_width)``,
and :meth:`~ogm_ppl.testing.SensorContract.test_compiled_reading_model_matches_log_prob` checks that the
compiled functions give the ``log p(reading | f)`` of its ``log_prob``, and that its outcomes sum to one
(``tests/exploration/test_own_sensor.py`` explores with a Laplace range sensor this way).
"""

from ogm_ppl.sensors_compiled.gaussian import GaussianReading
from ogm_ppl.sensors_compiled.pattern import PatternReading
from ogm_ppl.sensors_compiled.registry import (
    ReadingKind,
    bin_prob,
    coord,
    draw,
    fill_row,
    is_continuous,
    kind_of,
    log_reading,
    num_outcomes,
    register,
    registered,
)

__all__ = [
    "CompiledReading",
    "GaussianReading",
    "PatternReading",
    "ReadingKind",
    "bin_prob",
    "coord",
    "draw",
    "fill_row",
    "is_continuous",
    "kind_of",
    "log_reading",
    "num_outcomes",
    "register",
    "registered",
]

#: any bundle the shipped sensors' ``compiled()`` returns (a sensor of one's own may return its own kind)
CompiledReading = GaussianReading | PatternReading
