"""Every map kernel passes :class:`~ogm_ppl.testing.KernelContract`: exact stationarity on enumerable 1D
and 2D problems, the checkpoint round trip and ``region=``, for each scan and update rule."""

import numpy as np

from ogm_ppl.inference.mcmc import CellGibbs, GuidedGibbs, KernelCycle, KernelMixture, MetropolisCell, PatchGibbs
from ogm_ppl.testing import KernelContract


class TestCellGibbsSystematic(KernelContract):
    def make_kernel(self, model, region=None):
        return CellGibbs(model, region=region)


class TestCellGibbsPermutation(KernelContract):
    def make_kernel(self, model, region=None):
        return CellGibbs(model, scan="permutation", region=region)


class TestCellGibbsRandomMetropolised(KernelContract):
    def make_kernel(self, model, region=None):
        return CellGibbs(model, scan="random", update="metropolised", region=region)


class TestMetropolisCellUniform(KernelContract):
    def make_kernel(self, model, region=None):
        return MetropolisCell(model, region=region)


class TestMetropolisCellEndpoint(KernelContract):
    def make_kernel(self, model, region=None):
        return MetropolisCell(model, proposal="endpoint", endpoint_weight=4.0, region=region)


class TestPatchGibbs(KernelContract):
    def make_kernel(self, model, region=None):
        return PatchGibbs(model, 3 if model.grid.ndim == 1 else (2, 2), region=region)


class TestPatchGibbsRandPatch(KernelContract):
    def make_kernel(self, model, region=None):
        return PatchGibbs(model, 2 if model.grid.ndim == 1 else (1, 3), p_rand_patch=0.3, region=region)


class TestPatchGibbsMetropolisedPermutation(KernelContract):
    def make_kernel(self, model, region=None):
        return PatchGibbs(
            model,
            3 if model.grid.ndim == 1 else (1, 2),
            scan="permutation",
            update="metropolised",
            p_rand_patch=0.2,
            region=region,
        )


class TestPatchGibbsRandomScan(KernelContract):
    def make_kernel(self, model, region=None):
        return PatchGibbs(model, 2 if model.grid.ndim == 1 else (1, 2), scan="random", region=region)


class _SharpGuide:
    """Confident, partly wrong proposals (logits +-3): many rejections, the hard case for exactness."""

    def cell_logits(self, model):
        g = np.random.default_rng(0)
        return 3.0 * g.standard_normal(model.num_cells)


class TestGuidedGibbs(KernelContract):
    supports_region = False

    def make_kernel(self, model, region=None):
        block = (1, 3) if model.grid.ndim == 1 else (2, 2)
        return GuidedGibbs(CellGibbs(model), _SharpGuide(), block=block, p_guide=0.5)


class TestKernelCycle(KernelContract):
    num_draws = 500  # the exact matrix carries the stationarity check; the draws check the sweeps follow it

    def make_kernel(self, model, region=None):
        patch = 3 if model.grid.ndim == 1 else (1, 2)
        return KernelCycle(
            [PatchGibbs(model, patch, region=region), CellGibbs(model, scan="permutation", region=region)]
        )


class TestKernelMixture(KernelContract):
    """One part per sweep, drawn with unequal weights: ``P = sum_i w_i P_i``."""

    num_draws = 500

    def make_kernel(self, model, region=None):
        patch = 3 if model.grid.ndim == 1 else (1, 2)
        return KernelMixture(
            [PatchGibbs(model, patch, region=region), CellGibbs(model, scan="permutation", region=region)],
            weights=[0.3, 0.7],
        )


class TestKernelCycleOwnStart(KernelContract):
    num_draws = 500

    def make_kernel(self, model, region=None):
        return KernelCycle(
            [
                MetropolisCell(model, region=region),
                PatchGibbs(model, 2 if model.grid.ndim == 1 else (2, 2), region=region),
            ],
            init="free",
        )
