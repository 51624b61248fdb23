"""Models: the occupancy map model as a Pyro program (:class:`OccupancyModel`, Section 2.2) and the
inverse-sensor-model update terms of traditional mapping (Delta families, Section 2.4)."""

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
    "PN",
    "BorensteinKoren",
    "DeltaFamily",
    "DeltaFileError",
    "Elfes",
    "MapDistribution",
    "MarshallBarfoot",
    "Moravec",
    "OccupancyModel",
    "Stachniss",
    "delta_by_name",
    "load_delta",
]
