"""Posterior summaries (``ogm_ppl.posterior``): Eq. (4.7) by hand, the exact path probability of the 1D
chain posterior on sets that include the ray's first cell against brute force, and the mutual
information of cell pairs against a hand-computed joint and against sums over the posterior's maps."""

import itertools
import math

import pytest
import torch

from ogm_ppl import OccupancyModel, raycast
from ogm_ppl.datasets import toy_1d
from ogm_ppl.inference.exact import brute_force, pose_constrained_1d
from ogm_ppl.posterior import first_hit_independent, mutual_information_from_joint
from ogm_ppl.priors import DataDriven1DPrior

from .inference.exact.test_exact import model_1d
from .inference.mcmc.test_gibbs import model_2d, states


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


# ------------------------------------------------------------------------------- mutual information


def test_mutual_information_of_a_hand_computed_joint():
    # joint of (a, b): P(00) = 0.4, P(01) = 0.1, P(10) = 0.2, P(11) = 0.3; P(a=1) = 0.5, P(b=1) = 0.4
    mi_ab = (
        0.4 * math.log(0.4 / (0.5 * 0.6))
        + 0.1 * math.log(0.1 / (0.5 * 0.4))
        + 0.2 * math.log(0.2 / (0.5 * 0.6))
        + 0.3 * math.log(0.3 / (0.5 * 0.4))
    )
    h_a = math.log(2.0)
    h_b = -(0.4 * math.log(0.4) + 0.6 * math.log(0.6))
    p = torch.tensor([0.5, 0.4], dtype=torch.float64)
    p11 = torch.tensor([[0.5, 0.3], [0.3, 0.4]], dtype=torch.float64)
    expect = torch.tensor([[h_a, mi_ab], [mi_ab, h_b]], dtype=torch.float64)
    torch.testing.assert_close(mutual_information_from_joint(p, p11), expect, rtol=0, atol=1e-12)
    # independent cells: zero; a copy: the entropy
    p11_ind = torch.outer(p, p)
    p11_ind.diagonal().copy_(p)
    torch.testing.assert_close(
        mutual_information_from_joint(p, p11_ind),
        torch.diag(torch.tensor([h_a, h_b], dtype=torch.float64)),
        rtol=0,
        atol=1e-12,
    )


def _entropy(p: torch.Tensor) -> torch.Tensor:
    terms = torch.where((p > 0) & (p < 1), -(p * torch.log(p) + (1 - p) * torch.log1p(-p)), torch.zeros_like(p))
    return terms


def test_mi_diagonal_is_cell_entropy():
    model = model_2d()
    post = brute_force(model)
    mi = post.mutual_information()
    torch.testing.assert_close(mi.diagonal(), _entropy(post.marginals), rtol=0, atol=1e-10)
    # an off-diagonal entry against the pair joint summed directly from the posterior's maps
    S, w = states(model), post.log_probs.exp()
    lat = model.latent
    off = mi[lat][:, lat] - torch.diag(mi[lat, lat])  # the most dependent latent pair, so doubling would show
    a_, b_ = divmod(int(off.argmax()), len(lat))
    i, j = int(lat[a_]), int(lat[b_])
    mi_ij = 0.0
    for a in (0, 1):
        for b in (0, 1):
            pab = float(w[(S[:, i] == a) & (S[:, j] == b)].sum())
            pa, pb = float(w[S[:, i] == a].sum()), float(w[S[:, j] == b].sum())
            mi_ij += pab * math.log(pab / (pa * pb)) if pab > 0 else 0.0
    assert float(mi[i, j]) == pytest.approx(mi_ij, abs=1e-10)
    assert mi_ij > 1e-4  # a pair that is dependent, so doubling would show
    # and the 1D chain posterior agrees on its diagonal too
    toy = toy_1d(num_cells=9, wall=1, readings=(4.0, 5.0, 4.0))
    m1 = OccupancyModel(toy.grid, raycast(toy.grid, toy.scans), model.sensor, DataDriven1DPrior(9, 1))
    pc = pose_constrained_1d(m1)
    torch.testing.assert_close(pc.mutual_information().diagonal(), _entropy(pc.marginals), rtol=0, atol=1e-10)
