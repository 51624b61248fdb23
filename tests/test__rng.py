"""Seeded library calls leave the caller's global random streams as they found them."""

import random

import numpy as np
import pyro
import torch

from ogm_ppl import GaussianRange, Grid, OccupancyModel, raycast
from ogm_ppl.datasets import stop_and_scan
from ogm_ppl.inference import CellGibbs, run_gibbs
from ogm_ppl.inference.variational import MeanFieldGuide, fit_guide
from ogm_ppl.priors import IndependentPrior


def _model():
    grid = Grid((8, 9))
    truth = np.zeros((8, 9), bool)
    truth[:, 7] = True
    data = stop_and_scan(truth, grid, num_poses=1, beams=12, max_range_cells=6, sigma_cells=1.0, seed=0)
    return OccupancyModel(grid, raycast(grid, data.scans), GaussianRange(1.0, p_rand=1e-3), IndependentPrior(0.3, 72))


def _draws():
    return torch.rand(3).tolist(), np.random.rand(3).tolist(), [random.random() for _ in range(3)]


def test_fit_guide_and_run_gibbs_do_not_reset_the_callers_streams():
    """``pyro.set_rng_seed`` once, then replicates of (seeded fit, seeded chain, a draw of one's own): each
    replicate's own draws differ, as they do without the library calls in between; the seeded calls themselves
    still reproduce."""
    model = _model()
    pyro.set_rng_seed(123)
    expected = [_draws() for _ in range(2)]
    pyro.set_rng_seed(123)
    got, fits, chains = [], [], []
    for _ in range(2):
        fits.append(fit_guide(model, MeanFieldGuide(model), steps=3, num_particles=4, progress=False))
        chains.append(run_gibbs(CellGibbs(model), 5, seed=7, progress=False).stats.marginals)
        got.append(_draws())
    assert got == expected
    assert fits[0] == fits[1]
    torch.testing.assert_close(chains[0], chains[1], rtol=0, atol=0)


def test_the_streams_are_restored_after_an_error_too():
    model = _model()
    pyro.set_rng_seed(5)
    expected = _draws()
    pyro.set_rng_seed(5)
    try:
        run_gibbs(CellGibbs(model), -1, seed=3, progress=False)
    except ValueError:
        pass
    assert _draws() == expected
