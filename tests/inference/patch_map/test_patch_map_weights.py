"""Patch-map weights against brute force."""

import numpy as np
import torch

from ogm_ppl.inference.exact import brute_force
from ogm_ppl.inference.patch_map import offline_patch_map

from .test_patch_map import toy_model


def test_single_patch_weights_are_the_exact_posterior():
    """One patch over every latent cell: its ``2^L`` normalised log weights are brute force's log
    posterior of each map (same bit order: bit ``b`` is the ``b``-th latent cell)."""
    K = 7
    model = toy_model(K=K + 1, lam=0.35, readings=np.array([3.0, 4.0, 3.0]), sigma=1.5)
    exact = brute_force(model)
    assert model.latent.tolist() == list(range(1, K + 1))
    pm = offline_patch_map(model, K, offset=1)
    assert pm.log_weights.shape == (1, 2**K)
    torch.testing.assert_close(torch.from_numpy(pm.log_weights[0]), exact.log_probs, rtol=0, atol=1e-10)
