"""Gibbs sampling restricted to a region (the speed-up the thesis suggests after Table 6.6, Section 6.2.1:
sample only mapped cells or cells near them). Cells outside the sampled set never change, and the chain's
marginals match the brute-force conditional ``p(m_R' | m_rest, z)`` given the frozen cells."""

import math

import numpy as np
import pytest
import torch

from ogm_ppl import GaussianRange, Grid, OccupancyModel, Scans, raycast
from ogm_ppl.inference.exact import brute_force
from ogm_ppl.inference.mcmc.gibbs import CellGibbs, MetropolisCell, PatchGibbs
from ogm_ppl.priors import IndependentPrior, MRFPrior, PatchTablePrior

SHAPE = (3, 4)  # K = 12 cells, 3 pose cells pinned: 9 latent, 512 maps


def model_3x4(prior: str) -> OccupancyModel:
    grid = Grid(SHAPE, resolution=1.0)
    poses = [
        [0.5, 0.5, 0.0],
        [0.5, 0.5, 0.0],
        [3.5, 2.5, math.pi],
        [0.5, 0.5, math.pi / 2],
        [1.5, 2.5, -math.pi / 2],
        [3.5, 2.5, -math.pi / 2],
    ]
    ranges = np.array([[2.2], [3.9], [1.4], [2.1], [1.6], [1.2]])
    scans = Scans(np.array(poses), np.array([0.0]), ranges, max_range=3.9, over_range="max")
    priors = {
        "independent": lambda: IndependentPrior(torch.linspace(0.25, 0.55, 12)),
        "mrf": lambda: MRFPrior(SHAPE, order=2, psi=0.5, cell_prior=0.35),
        "table2x2": lambda: PatchTablePrior(SHAPE, np.arange(16), np.r_[9, np.arange(1, 15) % 4 + 1, 5], patch=(2, 2)),
    }
    return OccupancyModel(grid, raycast(grid, scans), GaussianRange(0.9), priors[prior]())


INIT = torch.tensor([0, 1, 0, 1, 1, 0, 0, 1, 0, 1, 1, 0], dtype=torch.float64)  # the frozen values outside R'
REGION = np.array([1, 2, 5, 6])  # cells (0, 1), (0, 2), (1, 1), (1, 2)


def exact_conditional(model: OccupancyModel, init: torch.Tensor, sampled: np.ndarray) -> torch.Tensor:
    """Marginals (``K``) of ``p(m_sampled | m_rest = init_rest, z)`` by brute force over the latent cells."""
    post = brute_force(model)
    latent = model.latent
    L = len(latent)
    bits = (torch.arange(2**L)[:, None] >> torch.arange(L)) & 1  # bit j: latent cell j
    frozen = ~torch.from_numpy(np.isin(latent.numpy(), sampled))
    keep = (bits[:, frozen] == init[latent][frozen].long()).all(1)
    w = torch.softmax(post.log_probs[keep], 0)
    out = init.clone()
    out[model.known_free] = 0.0
    out[latent] = (w[:, None] * bits[keep].double()).sum(0)
    return out


KERNELS = {
    "cell": lambda m, r: CellGibbs(m, init=INIT, region=r),
    "cell_permutation": lambda m, r: CellGibbs(m, scan="permutation", init=INIT, region=r),
    "metropolis_random": lambda m, r: MetropolisCell(m, init=INIT, region=r),
    "patch2x2": lambda m, r: PatchGibbs(m, (2, 2), init=INIT, region=r),
    "patch2x2_offset": lambda m, r: PatchGibbs(m, (2, 2), offset=(1, 1), init=INIT, region=r),
    "patch_random": lambda m, r: PatchGibbs(m, (1, 2), scan="random", init=INIT, region=r),
}
# the independent prior: ogm_ppl.testing.KernelContract (test_kernel_contract.py) checks it exactly
CASES = [("mrf", "cell"), ("mrf", "patch2x2_offset"), ("table2x2", "patch2x2"), ("mrf", "patch_random")]


@pytest.mark.parametrize("prior, kernel", CASES)
def test_region_chain_samples_the_exact_conditional(prior, kernel):
    model = model_3x4(prior)
    k = KERNELS[kernel](model, REGION)
    sampled = k.sampled_cells()
    latent_region = np.intersect1d(REGION, model.latent.numpy())
    assert np.isin(latent_region, sampled).all()  # R' covers the latent region cells ...
    assert len(sampled) < len(model.latent)  # ... and leaves some latent cells frozen
    if kernel.startswith("cell") or kernel.startswith("metropolis"):
        np.testing.assert_array_equal(sampled, latent_region)
    torch.manual_seed(0)
    k.setup()
    start = k.state.copy()
    frozen = ~np.isin(np.arange(model.num_cells), sampled)
    n = 4000
    acc = np.zeros(model.num_cells)
    params = k.initial_params
    for _ in range(n):
        params = k.sample(params)
        np.testing.assert_array_equal(k.state[frozen], start[frozen])  # frozen cells never change
        acc += k.state
    exact = exact_conditional(model, INIT, sampled).numpy()
    np.testing.assert_allclose(acc[frozen] / n, exact[frozen], rtol=0, atol=1e-12)
    # 4 standard errors of a mean of 0/1 draws (sd <= 0.5), allowing an integrated autocorrelation of 10
    tol = 4 * 0.5 * math.sqrt(10 / n)
    err = np.abs(acc / n - exact).max()
    assert err < tol, (err, tol)


def test_region_forms_agree_and_none_is_the_whole_map():
    model = model_3x4("independent")
    mask_k = np.isin(np.arange(12), REGION)
    forms = [REGION, REGION[::-1].tolist() + [1], torch.from_numpy(mask_k), mask_k.reshape(SHAPE)]
    for f in forms:
        np.testing.assert_array_equal(CellGibbs(model, region=f).region, REGION)
        np.testing.assert_array_equal(
            PatchGibbs(model, (2, 2), region=f)._anchors, PatchGibbs(model, (2, 2), region=REGION)._anchors
        )
    full = PatchGibbs(model, (2, 2), region=np.ones(12, bool))
    np.testing.assert_array_equal(full._anchors, PatchGibbs(model, (2, 2))._anchors)
    np.testing.assert_array_equal(full.sampled_cells(), model.latent.numpy())
    np.testing.assert_array_equal(CellGibbs(model).sampled_cells(), model.latent.numpy())
    # a region cell at (0, 1) alone: only the 2 x 2 patch at (0, 0) holds it
    np.testing.assert_array_equal(PatchGibbs(model, (2, 2), region=[1])._anchors, [[0, 0]])


def test_bad_region_errors_clearly():
    model = model_3x4("independent")
    pinned = np.flatnonzero(model.known_free.numpy())
    bad = [
        (np.ones(11, bool), "shape"),
        (np.ones((4, 3), bool), "shape"),
        (np.array([0.0, 1.0]), "dtype"),
        (np.array([], dtype=np.int64), "empty"),
        ([], "empty"),
        (np.zeros(12, bool), "empty"),
        (np.array([3, 12]), r"\[0, 12\)"),
        (np.array([-1]), r"\[0, 12\)"),
        (np.array([[1, 2]]), "1D"),
        (pinned, "latent"),
    ]
    for region, match in bad:
        for make in (
            lambda r: CellGibbs(model, region=r),
            lambda r: PatchGibbs(model, (2, 2), region=r),
            lambda r: MetropolisCell(model, region=r),
        ):
            with pytest.raises(ValueError, match=match):
                make(region)
