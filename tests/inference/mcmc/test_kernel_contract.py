"""Every map kernel passes :class:`~ogm_ppl.testing.KernelContract`: exact stationarity on enumerable 1D
and 2D problems, the checkpoint round trip and ``region=``, for each scan and update rule."""

import numpy as np
import pytest
import torch

from ogm_ppl.inference.mcmc import CellGibbs, GuidedGibbs, KernelCycle, KernelMixture, MetropolisCell, PatchGibbs
from ogm_ppl.inference.mcmc.kernel import MapKernel
from ogm_ppl.testing import KernelContract
from ogm_ppl.testing.kernels import enumerate_maps


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


# ------------------------------------------------------------------ the contract catches biased kernels
class _TableMetropolis(MapKernel):
    """Random-scan single-cell Metropolis reading ``log p(m, z)`` from a table of every map (enumerable
    problems only): a new kernel written outside the library, with switches for the bugs that the one-sweep
    checks, started from the posterior, let through (a user's trial found each)."""

    def __init__(self, model, region=None, bias=0.0, pinned_too=False, stuck_cell=None) -> None:
        super().__init__(model, region=region)
        self.bias, self.pinned_too, self.stuck_cell = bias, pinned_too, stuck_cell

    def _set_up(self) -> None:
        super()._set_up()
        maps = enumerate_maps(self.model)
        self._table = self.model.log_joint(maps).numpy()
        self._bit = {int(c): j for j, c in enumerate(self.model.latent.tolist())}

    def _code(self) -> int:
        return sum(int(self.state[c]) << j for c, j in self._bit.items())

    def _sweep(self) -> int:
        cells = self._visit if not self.pinned_too else np.union1d(self._visit, np.flatnonzero(self._pinned))
        changed = 0
        u = torch.rand(2 * len(cells), dtype=torch.float64).numpy()
        m = self.state
        for i in range(len(cells)):
            k = int(cells[int(u[2 * i] * len(cells))])
            if k == self.stuck_cell:
                continue
            old = self._code()
            m[k] ^= 1
            new = self._code() if k in self._bit else old
            d = self._table[new] - self._table[old] + self.bias * (1 if m[k] else -1)
            if np.log(u[2 * i + 1]) < d:
                changed += 1
            else:
                m[k] ^= 1
            self.chain.updates += 1
        self._load_map(m)
        return changed


class TestTableMetropolis(KernelContract):
    """The correct table kernel passes the contract (the baseline of the bugs below)."""

    def make_kernel(self, model, region=None):
        return _TableMetropolis(model, region=region)


@pytest.mark.parametrize(
    "bug, problem",
    [({"bias": 0.15}, "crossing"), ({"pinned_too": True}, "2d"), ({"stuck_cell": 10}, "crossing")],
    ids=["prior-log-odds-off-by-0.15", "flips-the-pinned-cell", "never-visits-a-cell"],
)
def test_the_long_run_check_catches_a_biased_kernel(bug, problem):
    """Bugs that passed the one-sweep checks fail the long run: log-odds off by 0.15 (0.2 was caught
    before), flips of the robot's own (pinned) cell, a cell the kernel never visits."""

    class Buggy(TestTableMetropolis):
        def make_kernel(self, model, region=None):
            return _TableMetropolis(model, region=region, **bug)

    with pytest.raises(AssertionError):
        Buggy().test_contract_long_run_reaches_the_exact_marginals(problem)
