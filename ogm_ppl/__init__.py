"""ogm_ppl: occupancy grid mapping as probabilistic programs on PyTorch and Pyro.

Implements Merali (2020), "A Study of the Benefits of Cell Correlations in Occupancy Grid Mapping".
"""

import ogm_ppl._numba_inline  # noqa: F401  (numba inlines without its quadratic IR copy; before any compile)
from ogm_ppl.grid import Grid
from ogm_ppl.models.occupancy import OccupancyModel
from ogm_ppl.raycast import CellIndex, Rays, raycast
from ogm_ppl.scans import Scans
from ogm_ppl.sensors import GaussianRange, PatternMatch, SensorModel

__all__ = [
    "CellIndex",
    "GaussianRange",
    "Grid",
    "OccupancyModel",
    "PatternMatch",
    "Rays",
    "Scans",
    "SensorModel",
    "raycast",
]


def _installed_version() -> str:
    from importlib import metadata

    try:
        return metadata.version("ogm_ppl")
    except metadata.PackageNotFoundError:  # a source tree that was never installed
        return "0.0.0+unknown"


__version__ = _installed_version()
