"""Cell and patch Gibbs under a net field pass the kernel contract (exact stationarity on enumerable 1D and 2D
problems, restarts, checkpoints, ``region=``, long runs to the exact marginals), with nets of two filters of
``3 x 3`` (every window of the enumerable problems crosses the grid's edge)."""

from ogm_ppl import OccupancyModel
from ogm_ppl.inference.mcmc.gibbs import CellGibbs, PatchGibbs
from ogm_ppl.testing import KernelContract
from ogm_ppl.testing.kernels import enumerable_1d, enumerable_2d
from tests.priors.test_net_field import random_net


def _with(model, prior):
    return OccupancyModel(model.grid, model.rays, model.sensor, prior)


class _UnderNet(KernelContract):
    num_draws = 400
    num_sweeps_long = 2000

    def problem_1d(self):
        m = enumerable_1d()
        return _with(m, random_net(m.grid.shape, 3, 2, "relu", 8, scale=0.6))

    def problem_2d(self):
        m = enumerable_2d()
        return _with(m, random_net(m.grid.shape, 3, 2, "softplus", 9, scale=0.6))

    def problem_region(self):
        m = super().problem_region()
        return _with(m, random_net(m.grid.shape, 3, 2, "relu", 10, scale=0.6))


class TestCellGibbsUnderNet(_UnderNet):
    def make_kernel(self, model, region=None):
        return CellGibbs(model, region=region)


class TestPatchGibbsUnderNet(_UnderNet):
    def make_kernel(self, model, region=None):
        return PatchGibbs(model, 3 if model.grid.ndim == 1 else (2, 2), region=region)
