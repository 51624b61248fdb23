"""The kind registry: what each shipped kind declares, and which compiled loop a patch sweep runs for it."""

from __future__ import annotations

import numpy as np
import pytest

from ogm_ppl import Grid
from ogm_ppl.datasets import stop_and_scan
from ogm_ppl.inference._kernels import gibbs
from ogm_ppl.methods import MapProblem, RunContext, get_method
from ogm_ppl.priors import BorderPatchPrior, IndependentPrior, PatternFieldPrior
from ogm_ppl.priors.compiled import registry
from ogm_ppl.priors.compiled.registry import patch_allocates

from ..toy_checkerboard import KIND


def _border():
    rng = np.random.default_rng(0)
    b = rng.integers(0, 1 << 16, 200)
    i = rng.integers(0, 512, 200)
    return BorderPatchPrior((12, 12), b, i, rng.integers(1, 9, 200).astype(float), inner=(3, 3))


def test_tile_tables_alone_declare_allocation_free_patch_conditionals():
    assert patch_allocates(_border().compiled()) is False
    assert patch_allocates(IndependentPrior(0.3, 16).compiled()) is True
    assert patch_allocates(PatternFieldPrior((6, 6), np.zeros(512)).compiled()) is True


def test_register_defaults_to_the_runtime():
    class Bundle(tuple):
        pass

    f = registry._no_scratch
    try:
        registry.register(Bundle, cell_log_odds=f, patch_prior_weights=f, candidate_weights=f)
        assert registry._KINDS[Bundle].patch_allocates is True
        registry.register(Bundle, cell_log_odds=f, patch_prior_weights=f, candidate_weights=f, patch_allocates=False)
        assert registry._KINDS[Bundle].patch_allocates is False
    finally:
        registry._KINDS.pop(Bundle, None)


@pytest.fixture(scope="module")
def room():
    truth = np.zeros((12, 12), bool)
    truth[[0, -1], :] = truth[:, [0, -1]] = True
    grid = Grid(truth.shape, 1.0)
    data = stop_and_scan(
        truth, grid, route=np.array([[6.5, 6.5, 0.0]]), beams=24, max_range_cells=9, sigma_cells=0.5, seed=0
    )
    return MapProblem(grid, data.scans, sigma_cells=0.5)


def _loop_priors(dispatcher):
    return {str(sig[3]) for sig in dispatcher.signatures}


def test_a_patch_sweep_runs_the_loop_its_kind_declares(room):
    """The tile table's patch sweep compiles the runtime-free loop; the stencil kind's keeps the runtime."""
    method = get_method("gibbs")
    for prior in (KIND, "border:generated"):
        params = method.parse({"prior": prior, "sweeps": 2, "burn_in": 1, "patch": [3, 3]})
        method.run(params, room, RunContext(seed=0))
    lean, rt = _loop_priors(gibbs._candidate_loop_lean), _loop_priors(gibbs._candidate_loop_rt)
    assert any("Tiles" in s for s in lean) and not any("Tiles" in s for s in rt)
    assert any("Stencil" in s for s in rt) and not any("Stencil" in s for s in lean)
