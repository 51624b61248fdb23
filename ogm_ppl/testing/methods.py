"""Contract checks every map method must pass (:mod:`ogm_ppl.methods`), as a pytest mixin::

    class TestMyMethod(MethodContract):
        method = "endpoints"                 # its registered name
        params = {"level": 0.7}              # values over its defaults, small enough for a test

and gets, on a 1D problem (7 cells, three readings) and a 2D one (2 x 4 cells, four readings, max-range
readings among them), and for the map's form also the 2D readings on a 4 x 5 grid that no ray fully crosses:

* **registration**: the name resolves, every parameter is described (``ogm-ppl methods``), the defaults and
  ``params`` parse, and an unknown key is refused naming it (:class:`~ogm_ppl.methods.ParamError`);
* **a map**: ``run`` returns ``K`` float64 probabilities in ``[0, 1]`` (a map of another shape than the
  grid's is refused by the registry), a ``K`` bool ``observed`` mask within the cells some ray crosses (its
  traversal up to the sensor's range), and JSON-able ``details``;
* **reproducible**: two runs with one seed give the same map, bit for bit;
* **exact** (where ``exact_tolerance`` is set): the map's probabilities, with ``exact_params`` over
  ``params``, equal the brute-force posterior marginals of the model the method targets
  (:meth:`MethodContract.exact_model`) within the tolerance, on every cell, and exactly 0 on the cells the
  posterior never occupies (a sensor's own cell).
"""

from __future__ import annotations

import json
from typing import Any, ClassVar

import numpy as np

__all__ = ["MethodContract", "method_problems", "unreached_problem"]


def method_problems():
    """``[(name, MapProblem)]``: the contract's 1D and 2D problems (enumerable: 6 and 7 latent cells)."""
    from ogm_ppl.datasets import toy_1d
    from ogm_ppl.methods import MapProblem
    from ogm_ppl.testing.kernels import enumerable_2d_data

    toy = toy_1d(num_cells=7, wall=1, readings=(3.0, 4.0, 2.0))  # the problem of enumerable_1d
    grid, scans = enumerable_2d_data()
    return [("1d", MapProblem(toy.grid, toy.scans, sigma_cells=1.5)), ("2d", MapProblem(grid, scans, 0.9))]


def unreached_problem():
    """``("2d-unreached", MapProblem)``: the 2D problem's readings on a 4 x 5 grid, whose top rows no ray
    crosses (their cells must not be ``observed``), not square (a transposed map cannot pass)."""
    from ogm_ppl import Grid
    from ogm_ppl.methods import MapProblem
    from ogm_ppl.testing.kernels import enumerable_2d_data

    _, scans = enumerable_2d_data()
    return "2d-unreached", MapProblem(Grid((4, 5), resolution=1.0), scans, 0.9)


class MethodContract:
    """Pytest mixin: a map method's contract (module docstring). Set :attr:`method`; optionally
    :attr:`params`, :attr:`exact_tolerance` and :meth:`exact_model`."""

    #: the registered name
    method: str = ""
    #: parameter values over the method's defaults (small settings: few sweeps, few steps)
    params: ClassVar[dict[str, Any]] = {}
    #: values over :attr:`params` for the exact check (a sampler's longer run)
    exact_params: ClassVar[dict[str, Any]] = {}
    #: largest difference allowed between the map and the exact posterior marginals; ``None``: not checked
    #: (a method that does not target the posterior, such as traditional OGM)
    exact_tolerance: float | None = None

    def params_for(self, problem_name: str) -> dict[str, Any]:
        """The values for the ``"1d"`` or ``"2d"`` problem: :attr:`params` (override where a method takes
        other shapes in 1D, such as a patch of ``L`` cells instead of ``h x w``)."""
        return dict(self.params)

    def exact_model(self, problem, params):
        """The model whose posterior the method targets: by default the model of its
        :class:`~ogm_ppl.methods._model.ModelParams` (``prior``, ``lam``, ``sigma_cells``, ``sensor``,
        ``p_rand``) on ``problem``; for parameters without ``model``, ``prior``, ``lam`` and ``sigma_cells``."""
        model = getattr(params, "model", None)
        if callable(model):
            return model(problem)
        return problem.model(params.prior, params.lam, params.sigma_cells)

    def _method(self):
        from ogm_ppl.methods import get_method

        assert self.method, "set MethodContract.method to the registered name"
        return get_method(self.method)

    def _run(self, name, problem, seed: int = 0, extra=None):
        from ogm_ppl.methods import RunContext

        m = self._method()
        return m.run(m.parse({**self.params_for(name), **(extra or {})}), problem, RunContext(seed=seed))

    def test_registered_described_and_parsed(self):
        from ogm_ppl.methods import ParamError

        m = self._method()
        lines = m.describe()
        assert lines[0].startswith(f"{self.method}: ")
        for name in m.param_names():
            assert any(line.strip().startswith(f"{name} = ") for line in lines[1:]), name
        m.default_params()
        for name in ("1d", "2d"):
            m.parse(self.params_for(name))
        try:
            m.parse({**self.params, "no_such_parameter": 1})
        except ParamError as e:
            assert "no_such_parameter" in str(e)
        else:  # pragma: no cover - the failure
            raise AssertionError("an unknown parameter was accepted")

    def test_map_of_each_problem(self):
        for name, problem in [*method_problems(), unreached_problem()]:
            result = self._run(name, problem)
            K = problem.grid.num_cells
            p = result.probabilities
            assert p is not None and p.dtype == np.float64 and p.shape == (K,), name
            assert np.isfinite(p).all() and (p >= 0).all() and (p <= 1).all(), name
            observed = np.asarray(result.observed)
            assert observed.dtype == bool and observed.shape == (K,), name
            on_a_ray = np.zeros(K, bool)
            on_a_ray[problem.rays.cells] = True
            assert not (observed & ~on_a_ray).any(), name  # only cells on some ray
            if name == "2d-unreached":
                assert not on_a_ray.all()  # the problem has cells no ray crosses
            json.dumps(result.details)

    def test_reproducible_from_its_seed(self):
        for name, problem in method_problems():
            a, b = self._run(name, problem, seed=3), self._run(name, problem, seed=3)
            assert np.array_equal(a.probabilities, b.probabilities), name

    def test_matches_the_exact_posterior(self):
        if self.exact_tolerance is None:
            import pytest

            pytest.skip("no exact_tolerance: the method does not target the posterior")
        from ogm_ppl.inference.exact import brute_force

        m = self._method()
        for name, problem in method_problems():
            params = m.parse({**self.params_for(name), **self.exact_params})
            exact = brute_force(self.exact_model(problem, params)).marginals.numpy()
            got = self._run(name, problem, extra=self.exact_params).probabilities
            err = float(np.abs(got - exact).max())
            assert err <= self.exact_tolerance, (name, err)
            never = exact == 0  # cells no map of positive posterior mass occupies (the sensor's own cell)
            assert (got[never] == 0).all(), (name, "cells the posterior never occupies", got[never].tolist())
