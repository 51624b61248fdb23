"""KernelCycle beyond the kernel contract (``test_kernel_contract.py``, ``test_backoff_escape.py``): Pyro's
``MCMC`` drives it, bad parts are refused, its checkpoints name their parts, and a run's fingerprint tells
cycles of different parts apart."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from pyro.infer import MCMC

from ogm_ppl.inference.mcmc import (
    CellGibbs,
    KernelCycle,
    KernelMixture,
    KernelStateError,
    MetropolisCell,
    PatchGibbs,
    mixing_cycle,
)
from ogm_ppl.inference.mcmc.fingerprint import fingerprint
from ogm_ppl.inference.mcmc.runner import CheckpointError, RunningStats, run_gibbs
from ogm_ppl.testing.kernels import enumerable_1d, enumerable_2d


def cycle(model, init=None):
    return KernelCycle([PatchGibbs(model, (1, 2)), CellGibbs(model)], init=init)


def test_pyro_mcmc_drives_the_cycle_and_each_part_sweeps_once_per_sweep():
    model = enumerable_2d()
    k = cycle(model)
    torch.manual_seed(0)
    mcmc = MCMC(k, num_samples=40, warmup_steps=5, disable_progbar=True)
    mcmc.run()
    assert mcmc.get_samples()["m"].shape == (40, len(model.latent))
    mcmc.summary()  # runs
    assert k.sweeps == 45 and [p.sweeps for p in k.kernels] == [45, 45]
    d = k.diagnostics()
    assert [p["kind"] for p in d["parts"]] == ["PatchGibbs", "CellGibbs"]
    assert k.updates == sum(p.updates for p in k.kernels) and k.changes <= k.updates


def test_the_start_is_the_first_part_s_unless_given():
    model = enumerable_2d()
    a = cycle(model)
    assert a.init == "ogm"
    assert torch.equal(a.initial_params["m"], a.kernels[0].initial_params["m"])
    b = cycle(model, init="free")
    assert b.init == "free" and not b.initial_params["m"].any()


@pytest.mark.parametrize(
    "parts, error, match",
    [
        ([], ValueError, "at least one"),
        (["CellGibbs"], TypeError, "MapKernel"),
        ("other model", ValueError, "same model|another model"),
        ("twice", ValueError, "twice"),
    ],
)
def test_bad_parts_are_refused(parts, error, match):
    model = enumerable_2d()
    if parts == "other model":
        parts = [CellGibbs(model), CellGibbs(enumerable_2d())]
    elif parts == "twice":
        k = CellGibbs(model)
        parts = [k, k]
    with pytest.raises(error, match=match):
        KernelCycle(parts)


def test_a_state_of_another_cycle_is_refused_naming_the_part():
    model = enumerable_2d()
    a = cycle(model)
    a.setup()
    a.sample(a.current_params())
    state = a.state_dict()
    assert int(state["parts"]) == 2 and str(state["k0.kind"]) == "PatchGibbs" and str(state["k1.kind"]) == "CellGibbs"
    with pytest.raises(KernelStateError, match="'parts' must be 3"):
        KernelCycle([PatchGibbs(model, (1, 2)), CellGibbs(model), MetropolisCell(model)]).load_state_dict(state)
    swapped = KernelCycle([CellGibbs(model), PatchGibbs(model, (1, 2))])
    with pytest.raises(KernelStateError, match="part 0: a state of a PatchGibbs kernel"):
        swapped.load_state_dict(state)


def test_a_checkpoint_of_one_cycle_is_refused_by_another(tmp_path):
    model = enumerable_1d()
    a = KernelCycle([PatchGibbs(model, 2), CellGibbs(model)])
    b = KernelCycle([PatchGibbs(model, 3), CellGibbs(model)])
    assert fingerprint(a, RunningStats(model))["kernel"] != fingerprint(b, RunningStats(model))["kernel"]
    ck = tmp_path / "c.npz"
    run_gibbs(a, 5, RunningStats(model), seed=1, checkpoint=ck, progress=False)
    with pytest.raises(CheckpointError, match="kernel"):
        run_gibbs(b, 5, RunningStats(model), seed=1, checkpoint=ck, progress=False)
    # the same cycle resumes to the uninterrupted run's marginals
    full = RunningStats(model)
    run_gibbs(KernelCycle([PatchGibbs(model, 2), CellGibbs(model)]), 9, full, seed=1, progress=False)
    again = RunningStats(model)
    run_gibbs(KernelCycle([PatchGibbs(model, 2), CellGibbs(model)]), 9, again, seed=1, checkpoint=ck, progress=False)
    np.testing.assert_array_equal(again.marginals.numpy(), full.marginals.numpy())


def test_mixing_cycle_adds_the_moves_a_prior_s_sampler_lacks():
    model = enumerable_2d()
    tiles = mixing_cycle(model, (1, 2), init="free")
    assert [type(k).__name__ for k in tiles.kernels] == ["PatchGibbs", "CellGibbs"]
    assert (tiles.kernels[0].dr.size, tiles.init) == (2, "free")
    cells = mixing_cycle(model)
    assert [type(k).__name__ for k in cells.kernels] == ["CellGibbs", "PatchGibbs", "PatchGibbs"]
    assert [k.offset for k in cells.kernels[1:]] == [0, (1, 1)] and cells.kernels[1].L == 4


@pytest.mark.parametrize("make", [CellGibbs, lambda m: PatchGibbs(m, (1, 2)), MetropolisCell])
def test_a_handed_over_map_continues_as_a_set_one(make):
    """The unchecked hand-over of composite kernels (``_adopt_map``) builds the state ``set_state`` builds:
    the same first hits, and the same chain from the same seed."""
    model = enumerable_2d()
    m = torch.zeros(model.num_cells, dtype=torch.float64)
    m[model.latent[::2]] = 1.0
    a, b = make(model), make(model)
    a.setup(), b.setup()
    a.set_state(m)
    b._adopt_map(m.numpy().astype(np.uint8))
    np.testing.assert_array_equal(a.first_hit_state, b.first_hit_state)
    for k in (a, b):
        torch.manual_seed(3)
        for _ in range(5):
            k.sample(k.current_params())
    np.testing.assert_array_equal(a.state, b.state)


def test_a_kernel_that_extends_set_state_gets_the_checked_hand_over():
    class Counting(CellGibbs):
        loads = 0

        def _set_state(self, m) -> None:
            type(self).loads += 1
            super()._set_state(m)

    model = enumerable_2d()
    k = KernelCycle([PatchGibbs(model, (1, 2)), Counting(model)])
    k.setup()
    before = Counting.loads
    torch.manual_seed(0)
    for _ in range(3):
        k.sample(k.current_params())
    assert Counting.loads > before  # each stale hand-over went through its _set_state
    with pytest.raises(ValueError):
        Counting(model)._adopt_map(np.full(model.num_cells, 2, np.uint8))


# ------------------------------------------------------------------------------------------ KernelMixture
def mixture(model, weights=(0.25, 0.75)):
    return KernelMixture([PatchGibbs(model, (1, 2)), CellGibbs(model)], weights=list(weights))


def test_pyro_mcmc_drives_the_mixture_and_one_part_sweeps_per_sweep():
    """Each sweep runs exactly one part; over 2000 sweeps the parts are drawn at their weights (within 4
    binomial standard deviations: 4 * sqrt(2000 * 0.25 * 0.75) = 77 draws)."""
    model = enumerable_2d()
    k = mixture(model)
    torch.manual_seed(0)
    mcmc = MCMC(k, num_samples=1900, warmup_steps=100, disable_progbar=True)
    mcmc.run()
    mcmc.summary()  # runs
    counts = [p.sweeps for p in k.kernels]
    assert k.sweeps == 2000 and sum(counts) == 2000
    assert abs(counts[0] - 500) < 4 * np.sqrt(2000 * 0.25 * 0.75)
    assert k.updates == sum(p.updates for p in k.kernels)
    assert k.settings()["weights"] == [0.25, 0.75]


@pytest.mark.parametrize("weights", [[1.0], [1.0, 0.0], [1.0, -1.0], [1.0, float("nan")], [[0.5, 0.5]]])
def test_bad_mixture_weights_are_refused(weights):
    model = enumerable_2d()
    with pytest.raises(ValueError, match="weights must be 2 positive finite numbers"):
        KernelMixture([PatchGibbs(model, (1, 2)), CellGibbs(model)], weights=weights)


def test_a_mixture_checkpoint_resumes_and_refuses_other_weights(tmp_path):
    model = enumerable_1d()
    ck = tmp_path / "c.npz"
    full = RunningStats(model)
    run_gibbs(mixture(model), 9, full, seed=1, progress=False)
    run_gibbs(mixture(model), 5, RunningStats(model), seed=1, checkpoint=ck, progress=False)
    again = RunningStats(model)
    run_gibbs(mixture(model), 9, again, seed=1, checkpoint=ck, progress=False)
    np.testing.assert_array_equal(again.marginals.numpy(), full.marginals.numpy())
    a, b = mixture(model), mixture(model, (0.5, 0.5))
    a.setup()
    b.setup()
    with pytest.raises(KernelStateError, match="weights"):
        b.load_state_dict(a.state_dict())
    with pytest.raises(KernelStateError, match="cannot be loaded into a KernelCycle"):
        KernelCycle([PatchGibbs(model, (1, 2)), CellGibbs(model)]).load_state_dict(a.state_dict())


def test_mixing_cycle_draws_one_shifted_tiling_per_sweep_on_request():
    """``shifted="random"``: the tile and cell sweeps, then a mixture of the shifted tilings (3 x 3 tiles: by one
    and by two cells), one of them per sweep; ``shifted=True`` sweeps both."""
    model = enumerable_2d()
    both = mixing_cycle(model, (3, 3), shifted=True)
    assert [type(k).__name__ for k in both.kernels] == ["PatchGibbs", "CellGibbs", "PatchGibbs", "PatchGibbs"]
    one = mixing_cycle(model, (3, 3), shifted="random")
    assert [type(k).__name__ for k in one.kernels] == ["PatchGibbs", "CellGibbs", "KernelMixture"]
    mix = one.kernels[2]
    assert [k.offset for k in mix.kernels] == [k.offset for k in both.kernels[2:]] == [(1, 1), (2, 2)]
    np.testing.assert_array_equal(mix.weights, [0.5, 0.5])
    one.setup()
    params = one.current_params()
    for _ in range(10):
        params = one.sample(params)
    assert sum(k.sweeps for k in mix.kernels) == 10 == mix.sweeps
    with pytest.raises(ValueError, match="shifted must be False, True or 'random'"):
        mixing_cycle(model, (3, 3), shifted="both")
