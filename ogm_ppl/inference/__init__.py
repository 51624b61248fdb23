"""Inference: traditional OGM (log-odds), exact posteriors, MAP, and MCMC over whole maps."""

from . import exact, log_odds
from .gibbs import CellGibbs, MetropolisCell, PatchGibbs
from .guides import MeanFieldGuide, PatchGuide, fit_guide
from .log_odds import LogOddsMap, evidence_grid, evidence_grid_from_scans
from .map_estimate import MapEstimate, map_estimate
from .runner import GibbsRun, RunningStats, run_gibbs
from .structured_guides import ExactELBO, FirstHitGuide

__all__ = [
    "exact",
    "log_odds",
    "LogOddsMap",
    "evidence_grid",
    "evidence_grid_from_scans",
    "map_estimate",
    "MapEstimate",
    "CellGibbs",
    "PatchGibbs",
    "MetropolisCell",
    "RunningStats",
    "GibbsRun",
    "run_gibbs",
    "MeanFieldGuide",
    "PatchGuide",
    "FirstHitGuide",
    "ExactELBO",
    "fit_guide",
]
