"""``RunningStats`` against sums by hand: pair joints, path probabilities and their MI from a known list of
maps."""

import numpy as np
import pytest
import torch

from ogm_ppl.inference.mcmc.runner import RunningStats
from ogm_ppl.posterior import mutual_information_from_joint

from ..exact.test_exact import model_1d

MAPS = np.array(
    [
        [0, 1, 1, 0, 0, 1],
        [0, 0, 1, 1, 0, 0],
        [0, 1, 0, 1, 1, 0],
        [0, 0, 0, 0, 0, 0],
        [0, 1, 1, 1, 0, 1],
    ]
)
PAIRS = [[1, 2], [2, 3], [1, 4], [5, 1]]
PATHS = [[1, 2], [4, 5], [0], [2, 3, 4]]


def test_running_stats_match_frequencies():
    model = model_1d(5, [3.0])
    assert model.num_cells == MAPS.shape[1]
    st = RunningStats(model, pairs=PAIRS, paths=PATHS)
    for m in MAPS:
        st.update(torch.tensor(m, dtype=torch.float64))
    assert st.n == len(MAPS)
    np.testing.assert_allclose(st.marginals.numpy(), MAPS.mean(0), rtol=0, atol=1e-15)
    pair = [np.mean(MAPS[:, a] * MAPS[:, b]) for a, b in PAIRS]
    np.testing.assert_allclose(st.pair_joint().numpy(), pair, rtol=0, atol=1e-15)  # 2/5, 2/5, 1/5, 2/5
    free = [np.mean((MAPS[:, p] == 0).all(1)) for p in PATHS]
    np.testing.assert_allclose(st.prob_free().numpy(), free, rtol=0, atol=1e-15)  # 1/5, 2/5, 1, 1/5
    p = MAPS.mean(0)
    for j, (a, b) in enumerate(PAIRS):
        mi = mutual_information_from_joint(
            torch.tensor([p[a], p[b]]), torch.tensor([[p[a], pair[j]], [pair[j], p[b]]])
        )[0, 1]
        assert st.mutual_information()[j].item() == pytest.approx(mi.item(), abs=1e-15)


def test_trace_before_any_sample_is_empty_and_survives_a_round_trip():
    """No sample yet: the trace has zero rows (not a row of zeros), also after a state round trip;
    then one row per update."""
    model = model_1d(5, [3.0])
    st = RunningStats(model, trace_cells=[2, 4])
    assert st.trace().shape == (0, 2)
    again = RunningStats(model, trace_cells=[2, 4])
    again.load_state_dict(st.state_dict())
    assert again.trace().shape == (0, 2)
    again.update(torch.tensor(MAPS[0], dtype=torch.float64))
    np.testing.assert_array_equal(again.trace(), [[1, 0]])
