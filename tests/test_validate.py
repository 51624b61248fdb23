"""Maps and numeric options are checked in one place: 0/1 maps only, options named when refused."""

import math

import numpy as np
import pytest
import torch

from ogm_ppl import GaussianRange, OccupancyModel, raycast
from ogm_ppl._validate import as_binary_maps, finite_number
from ogm_ppl.datasets import THESIS_TOY_READINGS, toy_1d
from ogm_ppl.inference.exact.map_estimate import map_estimate
from ogm_ppl.inference.patch_map.maps import offline_patch_map
from ogm_ppl.priors import IndependentPrior

K = 12


@pytest.fixture(scope="module")
def model():
    toy = toy_1d(num_cells=K, readings=THESIS_TOY_READINGS[:2], wall=6)
    return OccupancyModel(toy.grid, raycast(toy.grid, toy.scans), GaussianRange(1.0), IndependentPrior(0.3, K))


BAD_MAPS = {
    "half": (np.full(K, 0.5), ValueError, "only 0 and 1"),
    "nan": (np.full(K, np.nan), ValueError, "NaN"),
    "two": (np.full(K, 2.0), ValueError, "only 0 and 1"),
    "string": ("0" * K, TypeError, "0/1 array"),
    "object": (np.array(["a"] * K), TypeError, "numeric"),
    "short": (np.zeros(K - 1), ValueError, f"{K} cells"),
}


@pytest.mark.parametrize("case", [c for c in BAD_MAPS if c != "string"])
def test_map_estimate_init_must_be_binary(model, case):
    """(A string ``init`` is a mode name, 'occupied', ..., refused by name.)"""
    value, exc, msg = BAD_MAPS[case]
    with pytest.raises(exc, match=msg):
        map_estimate(model, init=value)


@pytest.mark.parametrize("case", [c for c in BAD_MAPS if c != "string"])
def test_offline_patch_map_reference_must_be_binary(model, case):
    value, exc, msg = BAD_MAPS[case]
    with pytest.raises(exc, match=msg):
        offline_patch_map(model, patch=2, reference=value)


@pytest.mark.parametrize("case", list(BAD_MAPS))
def test_log_joint_refuses_bad_maps(model, case):
    value, exc, msg = BAD_MAPS[case]
    with pytest.raises(exc, match=msg):
        model.log_joint(value)


def test_good_maps_pass_unchanged(model):
    m = np.array([0, 1] * (K // 2))
    assert as_binary_maps(m, K, "m").dtype == torch.float64
    assert torch.equal(as_binary_maps(m.reshape(2, -1), K, "m", flatten=True), torch.from_numpy(m).double())
    est = map_estimate(model, init=m)
    assert math.isfinite(est.log_joint)
    assert math.isfinite(float(model.log_joint(torch.from_numpy(m))))


@pytest.mark.parametrize(
    "value, exc",
    [(float("nan"), ValueError), (float("inf"), ValueError), (-5, ValueError), ("3", TypeError), (True, TypeError)],
)
def test_finite_number_names_the_option(value, exc):
    with pytest.raises(exc, match="no_return"):
        finite_number(value, "no_return", minimum=0.0, strict=True)


def test_finite_number_bounds():
    assert finite_number(0, "x", minimum=0.0) == 0.0
    with pytest.raises(ValueError, match=r"> 0\.0"):
        finite_number(0, "x", minimum=0.0, strict=True)
    with pytest.raises(ValueError, match="<= 1"):
        finite_number(2, "x", maximum=1)
