"""Resuming ``run_gibbs`` from a checkpoint restores torch's random generator too: a run interrupted,
with torch's global generator disturbed before it resumes, ends bit for bit where the uninterrupted run
does (cell, patch and metropolised kernels)."""

import numpy as np
import pytest
import torch

from ogm_ppl import OccupancyModel, raycast
from ogm_ppl.datasets import toy_1d
from ogm_ppl.inference.mcmc.gibbs import CellGibbs, MetropolisCell, PatchGibbs
from ogm_ppl.inference.mcmc.runner import RunningStats, run_gibbs
from ogm_ppl.priors import IndependentPrior

from .test_gibbs import model_2d


@pytest.mark.parametrize(
    "make",
    [lambda m: CellGibbs(m, init="prior"), lambda m: PatchGibbs(m, 3, p_rand_patch=0.2), lambda m: MetropolisCell(m)],
    ids=["cell", "patch", "metropolis"],
)
def test_resume_restores_torch_rng(tmp_path, make):
    """Interrupt, then disturb torch's global generator before resuming: bit for bit all the same."""
    toy = toy_1d(num_cells=16, readings=(6.0, 7.0, 6.0, 9.0))
    model = OccupancyModel(toy.grid, raycast(toy.grid, toy.scans), model_2d().sensor, IndependentPrior(0.3, 16))
    full = run_gibbs(make(model), 300, RunningStats(model, trace_cells=[6]), warmup=10, seed=11, progress=False)
    ck = tmp_path / "ck.npz"
    part = run_gibbs(
        make(model),
        300,
        RunningStats(model, trace_cells=[6]),
        warmup=10,
        seed=11,
        checkpoint=ck,
        checkpoint_every=40,
        stop_after=97,
        progress=False,
    )
    assert part.interrupted and part.sweeps == 97
    torch.manual_seed(999)
    torch.rand(1000)
    rest = run_gibbs(
        make(model),
        300,
        RunningStats(model, trace_cells=[6]),
        warmup=10,
        seed=11,
        checkpoint=ck,
        checkpoint_every=40,
        progress=False,
    )
    assert not rest.interrupted and rest.sweeps == 310
    assert np.array_equal(full.state, rest.state)
    assert torch.equal(full.stats.marginals, rest.stats.marginals)
    assert np.array_equal(full.stats.trace(), rest.stats.trace())
