"""The gibbs method's ``warm_thesis`` start: an exact patch chain started where sweeps of the thesis's border
update end (reproducible from the seed, refused where it means nothing)."""

from __future__ import annotations

import numpy as np
import pytest

from ogm_ppl.methods import RunContext, get_method
from ogm_ppl.methods.params import ParamError

from .test_registry import box  # noqa: F401  (the fixture)

BORDER = {"prior": "border_bo:generated", "patch": [3, 3], "sweeps": 3, "burn_in": 0}


def test_warm_thesis_starts_the_exact_chain_from_the_thesis_update(box, monkeypatch):  # noqa: F811
    from ogm_ppl.inference.mcmc import PatchGibbs

    _, problem = box
    method = get_method("gibbs")
    warm = method.parse({**BORDER, "warm_thesis": 4})
    a = method.run(warm, problem, RunContext(seed=5)).probabilities
    b = method.run(warm, problem, RunContext(seed=5)).probabilities
    cold = method.run(method.parse(BORDER), problem, RunContext(seed=5)).probabilities
    assert np.array_equal(a, b) and not np.array_equal(a, cold)
    # the exact kernel's starting map is the thesis kernel's state after the warm sweeps
    made = []
    import ogm_ppl.inference.mcmc as mcmc

    monkeypatch.setattr(mcmc, "PatchGibbs", lambda *a, **kw: made.append(PatchGibbs(*a, **kw)) or made[-1])
    method.run(warm, problem, RunContext(seed=5))
    thesis, exact = made
    assert thesis.update == "thesis" and exact.update == "gibbs"
    start = exact._initial_map().numpy()
    assert start.shape == (problem.grid.num_cells,)
    assert np.array_equal(start, thesis.state.astype(np.float64))


@pytest.mark.parametrize(
    "values", [{"warm_thesis": 2, "patch": 1}, {"warm_thesis": 2, "patch": [3, 3], "update": "thesis"}]
)
def test_warm_thesis_is_refused_where_it_means_nothing(values):
    with pytest.raises(ParamError, match="warm_thesis"):
        get_method("gibbs").parse(values)
