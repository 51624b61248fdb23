"""IncrementalLogits: the guide's logits kept as features change on a few cells stay within the float32 bound of
the float64 network on the new features (the bound of ``test_amortised_fast``), only cells within the network's
reach of a change are recomputed, and every other cell keeps its logits; through oneDNN's fused convolution and
through ``conv2d`` and ``relu``, with small and large tiles (a tile larger than the grid, tiles across its far
edge)."""

import pytest
import torch

from ogm_ppl.inference.variational import amortised_incremental
from ogm_ppl.inference.variational.amortised_incremental import IncrementalLogits
from ogm_ppl.inference.variational.amortised_net import GuideArchitecture, GuideNet
from tests.inference.variational.test_amortised_fast import exact_logits_and_bound


def _near(changed: torch.Tensor, reach: int) -> torch.Tensor:
    """Cells within ``reach`` (Chebyshev) of a changed cell."""
    pooled = torch.nn.functional.max_pool2d(changed.float()[None, None], 2 * reach + 1, 1, reach)
    return pooled[0, 0].bool()


def _check_updates(arch: GuideArchitecture, shape: tuple[int, int], changes, symmetrize: bool, seed: int) -> None:
    torch.manual_seed(seed)
    net = GuideNet(arch)
    gen = torch.Generator().manual_seed(seed + 3)
    x = torch.rand((arch.in_channels, *shape), generator=gen, dtype=torch.float32)
    inc = IncrementalLogits(net, x, symmetrize)
    exact, bound = exact_logits_and_bound(net, x[None], symmetrize)
    assert ((inc.logits.double() - exact[0]).abs() <= bound[0]).all()
    reach = sum(arch.dilations)
    for rows, cols in changes:
        changed = torch.zeros(shape, dtype=torch.bool)
        changed[rows, cols] = True
        before = inc.logits.clone()
        x = x.clone()
        x[:, changed] = torch.rand((arch.in_channels, int(changed.sum())), generator=gen, dtype=torch.float32)
        done = inc.update(x, changed)
        assert done[changed].all() and not done[~_near(changed, reach)].any()
        assert torch.equal(inc.logits[~done], before[~done])
        assert torch.equal(inc.features, x)
        exact, bound = exact_logits_and_bound(net, x[None], symmetrize)
        assert ((inc.logits.double() - exact[0]).abs() <= bound[0]).all()


@pytest.mark.parametrize("symmetrize", [False, True])
def test_incremental_logits_equal_a_full_pass_after_updates(symmetrize):
    """Features changed on a few cells twice (a wall of cells, a single cell at the grid's corner)."""
    arch = GuideArchitecture(4, (1, 2, 1), (0, 0), "p21")
    _check_updates(arch, (12, 17), [(slice(5, 6), slice(2, 8)), (slice(0, 1), slice(16, 17))], symmetrize, 1)


@pytest.mark.parametrize("fused", [True, False])
def test_large_dilations_read_tiles_across_the_grid_edge(fused, monkeypatch):
    """Dilations 1 and 9 (tiles of 8 and 18 cells a side, larger than the grid's 11 rows): changes at the far
    corner, at the near corner, on a scattered set and on every cell; the convolutions fused (oneDNN's, where
    this torch has them) and as ``conv2d`` and ``relu``."""
    monkeypatch.setattr(amortised_incremental, "_FUSED", fused and amortised_incremental._FUSED)
    arch = GuideArchitecture(3, (1, 9), (0, 0), "p21")
    every = (slice(None), slice(None))
    changes = [
        (slice(10, 11), slice(13, 15)),
        (slice(0, 2), slice(0, 1)),
        (slice(1, None, 4), slice(2, None, 5)),
        every,
    ]
    _check_updates(arch, (11, 15), changes, False, 2)


def test_the_work_of_an_update_is_its_cells_and_tiles():
    """One changed cell in the middle of a 30 x 30 grid, dilations 1 and 2: the layers write 3 x 3 and 7 x 7 cells, on
    one tile of 8 x 8 cells each (the tiles are anchored at the reach's box, which holds every written cell);
    no changed cell: no work."""
    arch = GuideArchitecture(2, (1, 2), (0, 0), "p21")
    torch.manual_seed(0)
    x = torch.rand((arch.in_channels, 30, 30), dtype=torch.float32)
    inc = IncrementalLogits(GuideNet(arch), x)
    assert inc.last_work == []
    changed = torch.zeros((30, 30), dtype=torch.bool)
    changed[15, 15] = True
    inc.update(x + 1, changed)
    assert inc.last_work == [(9, 64), (49, 64)]
    inc.update(x, torch.zeros((30, 30), dtype=torch.bool))
    assert inc.last_work == [(0, 0), (0, 0)]
