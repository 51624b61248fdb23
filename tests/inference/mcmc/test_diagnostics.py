"""Dispersed starts and the R-hat agreement of chains from them (ogm_ppl.inference.mcmc.diagnostics)."""

import math
from functools import partial

import numpy as np
import pytest
import torch

from ogm_ppl.inference.mcmc import CellGibbs, ParallelTempering, RunningStats, run_gibbs
from ogm_ppl.inference.mcmc.diagnostics import STARTS, rhat_agreement, run_from_starts, split_rhat, start_maps
from ogm_ppl.inference.mcmc.kernel import initial_map
from ogm_ppl.testing.kernels import enumerable_1d, enumerable_2d


def _traces(seed: int = 0) -> np.ndarray:
    """3 chains x 400 sweeps x 4 cells: frozen apart, constant everywhere, well mixed, apart in mean."""
    rng = np.random.default_rng(seed)
    x = np.zeros((3, 400, 4))
    x[1, :, 0] = 1.0  # chain 1 stuck at 1, the others at 0
    x[:, :, 2] = rng.random((3, 400)) < 0.4
    x[:, :, 3] = rng.random((3, 400)) < np.array([0.1, 0.5, 0.9])[:, None]
    return x


def test_rhat_agreement_counts_the_cells_the_chains_agree_on():
    x = _traces()
    a = rhat_agreement(x)
    rhat = a["rhat"]
    assert math.isinf(rhat[0]) and math.isnan(rhat[1]) and rhat[2] < 1.05 and rhat[3] > 1.25
    np.testing.assert_array_equal(rhat, split_rhat(x).numpy())
    assert (a["cells"], a["varying"], a["frozen_apart"]) == (4, 3, 1)
    assert a["fraction_below"] == pytest.approx(1 / 3) and a["fraction_below_all"] == pytest.approx(2 / 4)
    assert a["rhat_max"] == math.inf and a["threshold"] == 1.05
    sub = rhat_agreement(x, cells=[2, 3], threshold=1.2)
    assert (sub["cells"], sub["varying"], sub["frozen_apart"]) == (2, 2, 0) and sub["fraction_below"] == 0.5
    for bad, kw, match in (
        (x[0], {}, "chains x sweeps x cells"),
        (x[:1], {}, "at least 2 chains"),
        (x, {"threshold": 1.0}, "threshold"),
        (x, {"cells": [4]}, "positions"),
    ):
        with pytest.raises(ValueError, match=match):
            rhat_agreement(bad, **kw)


def test_start_maps():
    model = enumerable_2d()
    pinned = model.known_free.numpy()
    rng = torch.get_rng_state()
    s = start_maps(model, ("ogm", "free", "occupied", "prior"), seed=4)
    assert torch.equal(torch.get_rng_state(), rng), "a prior start must leave the global generator alone"
    assert list(s) == ["ogm", "free", "occupied", "prior"]
    torch.testing.assert_close(s["ogm"], initial_map(model, "ogm"))
    assert s["free"].sum() == 0 and torch.equal(s["occupied"], (~model.known_free).double())
    torch.manual_seed(4)
    torch.testing.assert_close(s["prior"], initial_map(model, "prior"))
    for m in s.values():
        assert m.shape == (model.num_cells,) and (m[pinned] == 0).all()
    assert set(STARTS) >= {"ogm", "free", "prior", "guide"}
    with pytest.raises(ValueError, match="unknown start"):
        start_maps(model, ("ogm", "thresholded"))


@pytest.mark.parametrize("kind", ["cell", "tempering"])
def test_run_from_starts_runs_one_seeded_chain_per_start(kind):
    model = enumerable_1d(5)
    make = partial(CellGibbs, model) if kind == "cell" else partial(ParallelTempering, model, (1.0, 0.5))
    starts = start_maps(model, ("free", "occupied", "ogm"))
    cells = model.latent.numpy()[:3]
    res = run_from_starts(make, starts, 30, cells, warmup=2, seed=5)
    assert res.starts == ["free", "occupied", "ogm"] and res.traces().shape == (3, 30, 3)
    for c, m in enumerate(starts.values()):  # chain c is make(init=start) run with seed 5 + c
        stats = RunningStats(model, trace_cells=cells)
        run_gibbs(make(init=m), 30, stats, warmup=2, seed=5 + c, progress=False)
        np.testing.assert_array_equal(stats.trace(), res.traces()[c])
    assert rhat_agreement(res)["cells"] == 3
    with pytest.raises(ValueError, match="at least one start"):
        run_from_starts(make, {}, 5, cells)


def test_summary_gives_each_cell_its_own_n_eff_under_pyro_mcmc(capsys):
    """``MCMC.summary()``'s table with one ``n_eff`` per cell: a cell pinned by the data (constant in every
    draw) gets NaN alone, where Pyro's estimator makes every cell NaN; the rest equal :func:`ess` of the same
    draws, and Pyro's own estimator is restored afterwards."""
    import pyro.ops.stats as pyro_stats
    from pyro.infer import MCMC
    from pyro.infer.mcmc.util import summary as pyro_summary

    from ogm_ppl.inference.mcmc.diagnostics import ess, print_summary, summary

    torch.manual_seed(0)
    mcmc = MCMC(CellGibbs(enumerable_1d()), num_samples=300, warmup_steps=20, num_chains=1, disable_progbar=True)
    mcmc.run()
    draws = mcmc.get_samples(group_by_chain=True)["m"]
    x = torch.cat([draws, torch.zeros_like(draws[..., :1])], -1)  # one more cell, never occupied
    assert torch.isnan(pyro_summary({"m": x})["m"]["n_eff"]).all()  # Pyro's: NaN for every cell
    got = summary({"m": x})["m"]
    assert torch.isnan(got["n_eff"][-1]) and torch.isfinite(got["n_eff"][:-1]).all()
    torch.testing.assert_close(got["n_eff"][:-1], ess(draws), rtol=0, atol=0)
    assert torch.equal(summary(mcmc)["m"]["mean"], x[..., :-1].reshape(-1, x.shape[-1] - 1).mean(0))
    print_summary(mcmc)
    assert "n_eff" in capsys.readouterr().out
    assert pyro_stats.effective_sample_size.__module__ == "pyro.ops.stats"
