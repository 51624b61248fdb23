"""Priors over binary maps: the interface (:class:`MapPrior`), the independent prior and the 1D
data-driven prior; the higher-order MRF and learned patch priors plug into the same interface."""

from .base import MapPrior
from .data_driven_1d import DataDriven1DPrior
from .independent import IndependentPrior

__all__ = ["MapPrior", "IndependentPrior", "DataDriven1DPrior"]
