"""Models: the inverse-sensor-model update terms (Delta families) and, later, the Pyro map model."""

from ogm_ppl.models.delta import (
    PN,
    BorensteinKoren,
    DeltaFamily,
    DeltaFileError,
    Elfes,
    MarshallBarfoot,
    Moravec,
    Stachniss,
    delta_by_name,
    load_delta,
)
from ogm_ppl.models.occupancy import MapDistribution, OccupancyModel

__all__ = [
    "DeltaFamily",
    "BorensteinKoren",
    "Moravec",
    "MarshallBarfoot",
    "Stachniss",
    "Elfes",
    "PN",
    "delta_by_name",
    "load_delta",
    "DeltaFileError",
    "OccupancyModel",
    "MapDistribution",
]
