import math

import numpy as np
import pytest
import torch

from ogm_ppl.priors import IndependentPrior, MRFPrior, StencilPrior
from ogm_ppl.testing import PriorContract


class TestMRF1DOrder1(PriorContract):
    def make_prior(self, num_cells):
        return MRFPrior((num_cells,), order=1, psi=0.4, cell_prior=0.3)


class TestMRF1DOrder2(PriorContract):
    def make_prior(self, num_cells):
        return MRFPrior(num_cells, order=2, psi=0.5, cell_prior=torch.linspace(0.2, 0.6, num_cells))


class TestMRF2D4(PriorContract):
    def make_prior(self, num_cells):
        return MRFPrior((2, num_cells // 2), order=1, psi=0.3, cell_prior=0.4)


class TestMRF2D8(PriorContract):
    def make_prior(self, num_cells):
        return MRFPrior((2, num_cells // 2), order=2, psi=0.6, cell_prior=0.234)


class TestAnisotropicStencil(PriorContract):
    def make_prior(self, num_cells):
        return StencilPrior(
            (3, 2),
            unary=np.linspace(-1, 1, 6),
            offsets=[(1, 0), (0, 1), (1, 1)],
            coupling=[1.5, -0.7, 0.4],
            bias=[-0.3, 0.2, 0.1],
        )


def test_thesis_log_odds_formula():
    """l(m_k | neighbours) = l(lambda) + (n0 - n1) log psi (Section 5.2.1), on a 3 x 3 grid, centre cell."""
    from ogm_ppl.inference._kernels.cell_sweep import prior_log_odds

    lam, psi = 0.234, 0.3
    for order, nbrs in ((1, [1, 3, 5, 7]), (2, [0, 1, 2, 3, 5, 6, 7, 8])):
        p = MRFPrior((3, 3), order=order, psi=psi, cell_prior=lam)
        rng = np.random.default_rng(order)
        for _ in range(20):
            m = rng.integers(0, 2, 9).astype(np.uint8)
            n1 = int(m[nbrs].sum())
            n0 = len(nbrs) - n1
            want = math.log(lam / (1 - lam)) + (n0 - n1) * math.log(psi)
            assert prior_log_odds(p.compiled(), 4, m) == pytest.approx(want, abs=1e-12)
    # the joint is the product of cell priors and psi per unequal edge, up to a constant
    p = MRFPrior((4,), order=1, psi=psi, cell_prior=lam)
    maps = torch.tensor([[0, 0, 0, 0], [0, 1, 0, 0], [1, 1, 0, 1]], dtype=torch.float64)
    unequal = torch.tensor([0, 2, 2])
    occ = maps.sum(1)
    want = occ * math.log(lam) + (4 - occ) * math.log(1 - lam) + unequal * math.log(psi)
    got = p.log_prob(maps)
    torch.testing.assert_close(got - got[0], want - want[0])


def test_order_zero_is_the_independent_prior():
    p = MRFPrior((2, 3), order=0, cell_prior=0.3)
    q = IndependentPrior(0.3, 6)
    maps = ((torch.arange(64)[:, None] >> torch.arange(6)) & 1).double()
    torch.testing.assert_close(p.log_prob(maps) - p.log_normaliser(), q.log_prob(maps))


def test_bad_arguments():
    with pytest.raises(ValueError, match="psi"):
        MRFPrior((3, 3), psi=0.0)
    with pytest.raises(ValueError, match="cell_prior"):
        MRFPrior((3, 3), cell_prior=1.0)
    with pytest.raises(ValueError, match="order"):
        MRFPrior((3, 3), order=3)
    with pytest.raises(ValueError, match="J_d"):
        StencilPrior((3, 3), offsets=[(0, 1), (0, -1)], coupling=[1.0, 2.0])
    with pytest.raises(ValueError, match="1D"):
        StencilPrior((5,), offsets=[(1, 0)])
    with pytest.raises(ValueError, match="neighbour"):
        StencilPrior((3, 3), offsets=[(0, 0)])
