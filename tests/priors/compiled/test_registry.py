"""The kind registry: what each shipped kind declares, and which compiled loop a patch sweep runs for it."""

from __future__ import annotations

import numba
import numpy as np

from ogm_ppl.inference._kernels.candidate_sweep import _candidate_loop_lean, _candidate_loop_rt, candidate_loop_of
from ogm_ppl.methods import RunContext, get_method
from ogm_ppl.priors import BorderPatchPrior, IndependentPrior, PatternFieldPrior
from ogm_ppl.priors.compiled import registry
from ogm_ppl.priors.compiled.registry import patch_allocates

from ..test_extending import room  # noqa: F401 (the fixture)
from ..toy_checkerboard import KIND, CheckerboardPrior


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


def test_a_patch_sweep_runs_the_loop_its_kind_declares(room):  # noqa: F811
    """The tile table's patch sweep runs the runtime-free loop; the stencil kind's keeps the runtime (and both
    sweep)."""
    assert candidate_loop_of(numba.typeof(_border().compiled())) is _candidate_loop_lean
    assert candidate_loop_of(numba.typeof(CheckerboardPrior((6, 6)).compiled())) is _candidate_loop_rt
    method = get_method("gibbs")
    for prior in (KIND, "border:generated"):
        params = method.parse({"prior": prior, "sweeps": 2, "burn_in": 1, "patch": [3, 3]})
        p = method.run(params, room, RunContext(seed=0)).probabilities
        assert np.all((p >= 0) & (p <= 1))
