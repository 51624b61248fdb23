"""ogm_ppl: occupancy grid mapping as probabilistic programs on PyTorch and Pyro.

Implements Merali (2020), "A Study of the Benefits of Cell Correlations in Occupancy Grid Mapping".
"""

from .grid import Grid
from .models.occupancy import OccupancyModel
from .raycast import CellIndex, Rays, raycast
from .scans import Scans
from .sensors import GaussianRange, PatternMatch, SensorModel

__all__ = [
    "Grid",
    "Scans",
    "Rays",
    "CellIndex",
    "raycast",
    "SensorModel",
    "GaussianRange",
    "PatternMatch",
    "OccupancyModel",
]
__version__ = "0.1.0"
