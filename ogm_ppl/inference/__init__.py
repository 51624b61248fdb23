"""Inference: traditional OGM (log-odds); exact posteriors, MAP, patch maps and MCMC in later modules."""

from . import log_odds
from .log_odds import LogOddsMap, evidence_grid, evidence_grid_from_scans

__all__ = ["log_odds", "LogOddsMap", "evidence_grid", "evidence_grid_from_scans"]
