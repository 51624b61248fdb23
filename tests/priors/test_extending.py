"""A prior written in one file (tests/priors/toy_checkerboard.py) passes the prior contract and reaches
the compiled kernels, a spec and the command line with no other edit."""

import itertools
import re
import tomllib
from pathlib import Path

import numpy as np
import pytest
import torch

from ogm_ppl import Grid
from ogm_ppl.datasets import stop_and_scan
from ogm_ppl.methods import MapProblem, RunContext, get_method
from ogm_ppl.priors import prior_by_name, prior_kinds, unregister_prior
from ogm_ppl.priors.compiled import Stencil
from ogm_ppl.testing import PriorContract

from .toy_checkerboard import KIND, CheckerboardPrior  # registers the kind on import

ROOT = Path(__file__).resolve().parents[2]


class TestCheckerboardContract(PriorContract):
    def make_prior(self, num_cells):
        return CheckerboardPrior((num_cells,), beta=0.7)

    def make_prior_2d(self, shape):
        return CheckerboardPrior(shape, beta=0.7)


class TestContractSeesRowsOnlyIn2D:
    """A stencil bundle that drops the vertical couplings agrees with ``log_prob`` on every 1D map and is
    caught by the 2D checks only."""

    class _Contract(PriorContract):
        def make_prior(self, num_cells):
            return _NoVertical((num_cells,), beta=0.7)

        def make_prior_2d(self, shape):
            return _NoVertical(shape, beta=0.7)

    def test_1d_passes_and_2d_fails(self):
        c = self._Contract()
        c.make_prior_2d = lambda shape: None
        c.test_compiled_cell_conditional_matches_log_prob()
        with pytest.raises(AssertionError):
            self._Contract().test_compiled_cell_conditional_matches_log_prob()


class _NoVertical(CheckerboardPrior):
    def compiled(self):
        b = super().compiled()
        return b._replace(coupling=np.where(b.dr != 0, 0.0, b.coupling), bias=np.where(b.dr != 0, 0.0, b.bias))


def test_the_name_builds_it_and_it_declares_a_stencil():
    assert KIND in prior_kinds()
    p = prior_by_name(KIND, (5, 6))
    assert isinstance(p, CheckerboardPrior) and isinstance(p.compiled(), Stencil)
    with pytest.raises(ValueError, match="already registered"):
        from ogm_ppl.priors import register_prior

        register_prior(KIND, lambda shape, tables: p)
    with pytest.raises(ValueError, match="shipped"):
        unregister_prior("mrf")


@pytest.fixture(scope="module")
def room():
    truth = np.zeros((16, 16), bool)
    truth[[0, -1], :] = truth[:, [0, -1]] = True
    grid = Grid(truth.shape, 1.0)
    data = stop_and_scan(
        truth, grid, route=np.array([[8.5, 8.5, 0.0]]), beams=36, max_range_cells=12, sigma_cells=0.5, seed=0
    )
    return MapProblem(grid, data.scans, sigma_cells=0.5)


def test_gibbs_by_name_runs_the_compiled_sweeps(room, monkeypatch):
    """Single-cell and patch Gibbs never call the generic path (``log_prob_patch``) for this prior."""

    def generic(*args, **kwargs):
        raise AssertionError("the generic path was used")

    monkeypatch.setattr(CheckerboardPrior, "log_prob_patch", generic)
    method = get_method("gibbs")
    for patch in (1, [2, 2]):
        params = method.parse({"prior": KIND, "sweeps": 3, "burn_in": 1, "patch": patch})
        p = method.run(params, room, RunContext(seed=0)).probabilities
        assert p.shape == (room.grid.num_cells,) and np.all((p >= 0) & (p <= 1))


def test_a_spec_names_it(tmp_path):
    from ogm_ppl.experiment import parse_spec, run_experiment

    d = tomllib.loads((ROOT / "experiments" / "specs" / "smoke.toml").read_text())
    d["datasets"][0]["pose_fraction"] = 1.0
    d["algorithms"] = [{"name": "checker", "kind": "gibbs", "prior": KIND, "sweeps": 2, "burn_in": 1}]
    d["output"] = {"maps": False, "figures": False}
    r = run_experiment(parse_spec(d, "checker.toml"), tmp_path, scheduler="serial", progress=False)
    assert [x["algorithm"] for x in r.runs] == ["checker"]


def test_the_command_line_names_it(tmp_path, simulated_dataset):
    from ogm_ppl.cli import load_map, main

    sim = simulated_dataset
    out = tmp_path / "checker"
    assert (
        main(
            ["map", str(sim), "--method", "gibbs", "--prior", KIND, "--sweeps", "3", "--warmup", "1", "--out", str(out)]
        )
        == 0
    )
    assert load_map(out / "map.npz")["probabilities"].shape == (60, 60)


def test_a_module_registering_a_prior_can_be_reloaded(tmp_path, monkeypatch):
    """importlib.reload of a module that registers a kind (a notebook's edit-and-rerun) registers it anew;
    another factory under a taken name is still refused."""
    import importlib
    import sys

    from ogm_ppl.priors import IndependentPrior, register_prior

    (tmp_path / "my_reloaded_prior.py").write_text(
        "from ogm_ppl.priors import IndependentPrior, register_prior\n"
        "register_prior('reloaded_kind', lambda shape, tables: IndependentPrior(0.3, int(shape[0])))\n"
    )
    monkeypatch.syspath_prepend(str(tmp_path))
    try:
        mod = importlib.import_module("my_reloaded_prior")
        importlib.reload(mod)
        assert isinstance(prior_by_name("reloaded_kind", (4,)), IndependentPrior)
        with pytest.raises(ValueError, match=r"already registered \(my_reloaded_prior"):
            register_prior("reloaded_kind", lambda shape, tables: IndependentPrior(0.5, 4))
    finally:
        unregister_prior("reloaded_kind")
        sys.modules.pop("my_reloaded_prior", None)


def test_a_script_finds_a_kind_registered_in_a_module_named_in_the_environment():
    """Outside the command line (a script of one's own, ``experiments/calibration.py``), a kind that is not
    registered yet makes the lookup import the modules of ``$OGM_PPL_METHODS``; a typo there is named."""
    import os
    import subprocess
    import sys

    code = (
        "from ogm_ppl.priors import prior_by_name\n"
        "from ogm_ppl.sensors import sensor_by_name\n"
        "print(type(prior_by_name('toy_checker', (4, 5))).__name__)\n"
    )
    env = {**os.environ, "PYTHONPATH": str(ROOT), "OGM_PPL_METHODS": "tests.priors.toy_checkerboard"}
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, cwd=ROOT, timeout=120)
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip() == "CheckerboardPrior"
    env["OGM_PPL_METHODS"] = ""
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, cwd=ROOT, timeout=120)
    assert r.returncode != 0 and "unknown prior kind 'toy_checker'" in r.stderr
    env["OGM_PPL_METHODS"] = "no_such_module_xyz"
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, cwd=ROOT, timeout=120)
    assert r.returncode != 0 and "$OGM_PPL_METHODS names the module 'no_such_module_xyz'" in r.stderr


def test_an_unnormalised_prior_fails_the_contract_with_the_number():
    """A float32 prior that says it is normalised and is off by 1e-3 in log space: the contract's message
    gives the sum and the dtype.

    The offset is about 8,000 float32 roundings at 1 (eps 1.2e-7), so every CPU's float32 ``logsumexp``
    (vectorised or not, fused or not) reports it within a few roundings: the check depends on no rounding."""

    class _Float32(PriorContract):
        def make_prior(self, num_cells):
            return _Offset((num_cells,), beta=0.7)

    with pytest.raises(
        AssertionError, match=r"_Offset: log of the sum of p over all 64 maps is (\S+), .*dtype torch.float32"
    ) as err:
        _Float32().test_normalised_over_all_maps()
    reported = float(re.search(r"maps is (\S+),", str(err.value)).group(1))
    # the message prints 3 significant digits; float32 sums of 64 terms are off by far less than that
    assert reported == pytest.approx(_Offset.offset, rel=5e-3)


class _Offset(CheckerboardPrior):
    """The checkerboard's exactly normalised log_prob (log Z by enumeration, in float64) plus ``offset``, in
    float32, with ``normalised = True``: the contract takes it at its word and finds the sum off by ``offset``."""

    offset = 1e-3
    normalised = True

    def log_prob(self, m):
        every = torch.tensor(list(itertools.product([0.0, 1.0], repeat=m.shape[-1])), dtype=torch.float64)
        log_z = torch.logsumexp(super().log_prob(every), 0)
        return (super().log_prob(m) - log_z).to(torch.float32) + self.offset
