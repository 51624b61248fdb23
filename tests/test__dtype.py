"""The numeric contexts of :mod:`ogm_ppl._dtype`: each sets torch for its block and restores the caller's."""

import pytest
import torch

from ogm_ppl._dtype import float64, torch_threads


def test_float64_restores_the_default_dtype_also_on_error():
    before = torch.get_default_dtype()
    with pytest.raises(RuntimeError), float64():
        assert torch.zeros(1).dtype == torch.float64
        raise RuntimeError
    assert torch.get_default_dtype() == before


def test_torch_threads_sets_the_count_and_restores_the_callers():
    before = torch.get_num_threads()
    with pytest.raises(RuntimeError), torch_threads(1):
        assert torch.get_num_threads() == 1
        raise RuntimeError
    assert torch.get_num_threads() == before
