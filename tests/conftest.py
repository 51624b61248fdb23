"""Test configuration: float64 everywhere, every test seeded, a CI hypothesis profile."""

import os
import random

import numpy as np
import pytest
import torch
from hypothesis import HealthCheck, settings

settings.register_profile("ci", deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow])
settings.register_profile("dev", deadline=None, suppress_health_check=[HealthCheck.too_slow])
settings.load_profile("ci" if os.environ.get("CI") else "dev")


@pytest.fixture(autouse=True)
def _float64_and_seed():
    old = torch.get_default_dtype()
    torch.set_default_dtype(torch.float64)
    torch.manual_seed(0)
    np.random.seed(0)
    random.seed(0)
    yield
    torch.set_default_dtype(old)


@pytest.fixture
def simulated_dataset(tmp_path):
    """A small dataset file written by ``ogm-ppl simulate`` (a 60 x 60 office, 2 stops x 90 beams)."""
    from ogm_ppl.cli import main

    sim = tmp_path / "sim.npz"
    args = ["simulate", "--map", "office", "--size", "60", "--poses", "2", "--beams", "90"]
    assert main([*args, "--max-range-cells", "20", "--out", str(sim)]) == 0
    return sim
