"""Contract checks that every sensor model, prior and map kernel must pass (GPyTorch-style test mixins).

A new prior gets the generic suite by subclassing :class:`PriorContract` in a test module and writing one
factory method; likewise :class:`SensorContract` for sensor models, :class:`KernelContract` for map
kernels, :class:`MethodContract` for map methods (a registered name and its parameters) and
:class:`InputKindContract` for input kinds (a registered name and a small input of the kind). The checks
are exact (enumeration over small problems) or statistical with tolerances derived from the sample size;
the chi-square tests use :func:`multinomial_goodness_of_fit` (Pyro's test with SciPy's survival function).
"""

from ogm_ppl.testing._stats import multinomial_goodness_of_fit
from ogm_ppl.testing.inputs import InputKindContract
from ogm_ppl.testing.kernels import KernelContract
from ogm_ppl.testing.methods import MethodContract
from ogm_ppl.testing.priors import PriorContract
from ogm_ppl.testing.sensors import SensorContract

__all__ = [
    "InputKindContract",
    "KernelContract",
    "MethodContract",
    "PriorContract",
    "SensorContract",
    "multinomial_goodness_of_fit",
]
