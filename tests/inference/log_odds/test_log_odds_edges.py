"""Evidence-grid behaviour the main tests leave open (found by `make mutate`, issue 15)."""

import dataclasses

import pytest
import torch

from ogm_ppl import Grid, Scans, raycast
from ogm_ppl.inference import evidence_grid
from ogm_ppl.models import Moravec


def test_log_odds_map_is_immutable():
    """A ``LogOddsMap`` is a frozen value: its fields cannot be rebound after it is built."""
    rays = raycast(Grid.line(6), Scans.one_d([3.0], max_range=5.0))
    m = evidence_grid(rays, Moravec.haehnel())
    with pytest.raises(dataclasses.FrozenInstanceError):
        m.log_odds = torch.zeros(6)
    with pytest.raises(dataclasses.FrozenInstanceError):
        m.observed = torch.ones(6, dtype=torch.bool)
