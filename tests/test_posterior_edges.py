"""Posterior summaries the main tests leave open (found by `make mutate`, issue 15): Eq. (4.7) by
hand, and the exact path probability of the 1D chain posterior on sets that include the ray's first
cell, against brute force."""

import itertools

import pytest
import torch

from ogm_ppl.inference.exact import brute_force, pose_constrained_1d
from ogm_ppl.posterior import first_hit_independent

from .inference.exact.test_exact import model_1d


def test_first_hit_independent_by_hand():
    """``p(f = k) = p_k prod_{i<k} (1 - p_i)``, and "none" = ``prod_i (1 - p_i)``, last."""
    p = [0.2, 0.5, 0.1]
    expected = [0.2, 0.8 * 0.5, 0.8 * 0.5 * 0.1, 0.8 * 0.5 * 0.9]
    out = first_hit_independent(torch.tensor(p))
    assert out.dtype == torch.float64
    torch.testing.assert_close(out, torch.tensor(expected, dtype=torch.float64), rtol=0, atol=1e-15)
    assert abs(float(out.sum()) - 1.0) < 1e-15


def test_chain_prob_free_matches_brute_force_from_the_first_cell():
    """``ChainPosterior1D.prob_free`` equals brute force on every set of up to three cells of the
    ray, the robot's own cell (position 0 on the ray) included."""
    model = model_1d(6, [3.0, 4.0, 3.0])
    exact, chain = brute_force(model), pose_constrained_1d(model)
    cells = model.rays.ray(0).tolist()
    assert cells[0] == 0
    for r in (1, 2, 3):
        for subset in itertools.combinations(cells, r):
            assert chain.prob_free(list(subset)) == pytest.approx(exact.prob_free(list(subset)), abs=1e-12)
