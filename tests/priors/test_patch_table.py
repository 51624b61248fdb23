import numpy as np
import pytest
import torch

from ogm_ppl.priors import PatchTablePrior
from ogm_ppl.priors.patch_table import truncate_mass
from ogm_ppl.testing import PriorContract


class TestRunTable1D(PriorContract):
    def make_prior(self, num_cells):
        return PatchTablePrior((num_cells,), np.arange(8), [5, 1, 0, 2, 1, 0, 3, 4], patch=3)


class TestRunTable1DCutTiles(PriorContract):
    def make_prior(self, num_cells):
        return PatchTablePrior((num_cells,), np.arange(16), np.arange(16) % 5, patch=4, origin=1)


class TestSquareTable2D(PriorContract):
    def make_prior(self, num_cells):
        counts = np.random.default_rng(3).integers(0, 4, 16)
        counts[[0, 15]] = [20, 8]
        return PatchTablePrior((2, num_cells // 2), np.arange(16), counts, patch=(2, 2))


def test_code_convention_and_exact_log_prob():
    """code = sum m_i << i over the window's cells in row-major order; the map prior is the product of
    the tiles' tables (marginals for tiles cut by the edge)."""
    p = PatchTablePrior((2, 2), codes=[0, 0b0110, 0b1001], counts=[2, 1, 1], patch=(2, 2))
    m = torch.tensor([0.0, 1.0, 1.0, 0.0])  # cells (0, 1) and (1, 0): bits 1 and 2
    assert float(p.log_prob(m).exp()) == pytest.approx(0.25)
    assert float(p.log_prob(torch.tensor([1.0, 0.0, 0.0, 0.0])).exp()) == 0.0
    # a 2 x 2 table on a 2 x 3 grid: the second tile is cut; it keeps the marginal of its left column
    q = PatchTablePrior((2, 3), codes=[0, 0b0110, 0b1001], counts=[2, 1, 1], patch=(2, 2))
    m = torch.tensor([0.0, 1.0, 1.0, 1.0, 0.0, 0.0])  # tile 1: 0b0110 -> 1/4; cut tile: left column (1, 0)
    assert float(q.log_prob(m).exp()) == pytest.approx(0.25 * 0.25)


def test_truncation_keeps_the_most_likely_mass():
    codes = np.arange(6)
    probs = np.array([0.7, 0.2, 0.05, 0.03, 0.015, 0.005])
    c, p = truncate_mass(codes, probs, 0.99)
    assert c.tolist() == [0, 1, 2, 3, 4] and p.sum() == pytest.approx(1.0)
    prior = PatchTablePrior((9,), codes, probs, patch=3, mass=0.95)
    assert prior.num_configurations == 3


def test_bad_tables():
    with pytest.raises(ValueError, match="codes"):
        PatchTablePrior((6,), [8], [1.0], patch=3)
    with pytest.raises(ValueError, match="mass"):
        PatchTablePrior((6,), [0], [0.0], patch=3)
    with pytest.raises(ValueError, match="1D"):
        PatchTablePrior((6,), [0], [1.0], patch=(2, 2))
    with pytest.raises(ValueError, match="length"):
        PatchTablePrior((6,), [0, 1], [1.0], patch=3)


def test_five_by_five_table_is_sparse():
    rng = np.random.default_rng(0)
    codes = np.unique(rng.integers(0, 2**25, 300))
    p = PatchTablePrior((10, 10), np.r_[0, codes], np.r_[1000, np.ones(len(codes))], patch=(5, 5))
    assert p.num_configurations == len(codes) + 1
    assert torch.isfinite(p.log_prob(torch.zeros(100)))
    s = p.sample((2,), generator=torch.Generator().manual_seed(0))
    assert torch.isfinite(p.log_prob(s)).all()
