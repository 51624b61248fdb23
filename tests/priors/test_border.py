import numpy as np
import pytest
import torch

from ogm_ppl.priors import BorderPatchPrior
from ogm_ppl.testing import PriorContract


def _random_table(nb, ni, seed, density=1.0):
    rng = np.random.default_rng(seed)
    b, i = np.meshgrid(np.arange(2**nb), np.arange(2**ni), indexing="ij")
    counts = rng.integers(1, 6, b.shape).astype(float)
    counts[rng.random(b.shape) > density] = 0
    return b.ravel(), i.ravel(), counts.ravel()


class TestCellGivenNeighbours1D(PriorContract):
    num_prior_samples = 8000

    def make_prior(self, num_cells):
        return BorderPatchPrior((num_cells,), *_random_table(2, 1, 0), inner=1)


class TestRunGivenBorder1D(PriorContract):
    num_prior_samples = 8000

    def make_prior(self, num_cells):
        return BorderPatchPrior((num_cells,), *_random_table(2, 2, 1, density=0.7), inner=2, outside=0)


class TestCellGiven8Neighbours2D(PriorContract):
    num_prior_samples = 6000

    def make_prior(self, num_cells):
        b, i, c = _random_table(8, 1, 2)
        keep = b % 3 != 0  # a third of the borders unseen: they fall back to the marginal
        return BorderPatchPrior((2, num_cells // 2), b[keep], i[keep], c[keep], inner=(1, 1))


def test_border_layout_and_conditionals():
    """The 16 border cells of a 3 x 3 patch are the ring of its 5 x 5 window in row-major order."""
    p = BorderPatchPrior(
        (5, 5),
        border_codes=[0, 0, 0xFFFF],
        inner_codes=[0, 0b000010000, 0x1FF],
        counts=[3, 1, 1],
        inner=(3, 3),
        origin=(1, 1),
        unseen="zero",
    )
    lp = p.compiled()
    ring = [(r, c) for r in range(-1, 4) for c in range(-1, 4) if not (0 <= r < 3 and 0 <= c < 3)]
    assert list(zip(lp.w_dr[9:].tolist(), lp.w_dc[9:].tolist())) == ring
    assert p.num_borders == 2 and p.max_per_border == 2
    m = torch.zeros(25)
    centre = m.clone()
    centre[12] = 1.0
    # the middle tile (rows/cols 1..3) is one of 9 tiles; the others see off-grid cells as occupied and
    # have unseen borders (unseen="zero"), so compare conditionals of the middle tile only
    cells = torch.tensor([6, 7, 8, 11, 12, 13, 16, 17, 18])
    configs = torch.stack([torch.zeros(9), (torch.arange(9) == 4).double(), torch.ones(9)])
    both = p.log_prob_patch(torch.stack([m, centre]), cells, configs)
    assert torch.isinf(both).all()  # the outer tiles rule every map out here
    q = BorderPatchPrior((3, 3), border_codes=[0xFFFF, 0xFFFF], inner_codes=[0, 0b000010000], counts=[3, 1])
    got = q.log_prob(torch.stack([torch.zeros(9), (torch.arange(9) == 4).double(), torch.ones(9)]))
    np.testing.assert_allclose(got.exp().numpy(), [0.75, 0.25, 0.0])


def test_unseen_border_falls_back_to_marginal():
    q = BorderPatchPrior((1, 1), border_codes=[0, 0, 3], inner_codes=[0, 1, 1], counts=[2, 1, 1], inner=(1, 1))
    # every border cell off the grid reads as occupied: border 0xFF was never seen -> marginal p(1) = 2/4
    assert float(q.log_prob(torch.tensor([1.0])).exp()) == pytest.approx(0.5)
    z = BorderPatchPrior((1, 1), border_codes=[0], inner_codes=[0], counts=[1], inner=(1, 1), unseen="zero")
    assert float(z.log_prob(torch.tensor([0.0]))) == -np.inf


def test_bad_tables():
    with pytest.raises(ValueError, match="border codes"):
        BorderPatchPrior((4,), [4], [0], [1], inner=1)
    with pytest.raises(ValueError, match="inner codes"):
        BorderPatchPrior((4,), [0], [2], [1], inner=1)
    with pytest.raises(ValueError, match="unseen"):
        BorderPatchPrior((4,), [0], [0], [1], inner=1, unseen="maybe")
