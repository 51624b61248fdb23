"""Traditional occupancy grid mapping in log-odds (Section 2.4): evidence grids from any Delta family."""

from ogm_ppl.inference.log_odds.maps import (
    OCTOMAP_CLAMP,
    LogOddsMap,
    delta_table_for,
    evidence_grid,
    evidence_grid_from_scans,
)

__all__ = [
    "OCTOMAP_CLAMP",
    "LogOddsMap",
    "delta_table_for",
    "evidence_grid",
    "evidence_grid_from_scans",
]
