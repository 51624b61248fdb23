"""Exact inference (Chapter 2 and 3): brute force over 2^K maps, the pose-constrained 1D solution with the
independent or data-driven prior, Pyro enumeration, and the MAP map."""

from ogm_ppl.inference.exact.map_estimate import MapEstimate, map_estimate
from ogm_ppl.inference.exact.posteriors import (
    MAX_BRUTE_FORCE_CELLS,
    brute_force,
    pose_constrained_1d,
    pyro_enumeration,
)

__all__ = [
    "MAX_BRUTE_FORCE_CELLS",
    "MapEstimate",
    "brute_force",
    "map_estimate",
    "pose_constrained_1d",
    "pyro_enumeration",
]
