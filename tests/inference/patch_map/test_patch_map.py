import math

import numpy as np
import pytest
import torch

from ogm_ppl import GaussianRange, Grid, OccupancyModel, Scans, raycast
from ogm_ppl.datasets import THESIS_TOY_READINGS, simple_2d_example, toy_1d
from ogm_ppl.inference import evidence_grid
from ogm_ppl.inference.exact import brute_force, pose_constrained_1d
from ogm_ppl.inference.patch_map import (
    offline_patch_map,
    online_patch_map,
    reference_map,
    tile_patches,
)
from ogm_ppl.metrics import kl_divergence
from ogm_ppl.models import Elfes, Moravec
from ogm_ppl.priors import IndependentPrior


def toy_model(K=21, lam=0.5, known_free="sensor", readings=THESIS_TOY_READINGS, sigma=3.0):
    toy = toy_1d(num_cells=K, wall=1, readings=readings)
    rays = raycast(toy.grid, toy.scans)
    return OccupancyModel(toy.grid, rays, GaussianRange(sigma), IndependentPrior(lam, K), known_free=known_free)


@pytest.mark.parametrize("lam", [0.5, 0.3])
def test_online_L1_is_traditional_ogm(lam):
    model = toy_model(lam=lam, known_free=None)
    fwd = online_patch_map(model, 1)
    elfes = evidence_grid(model.rays, Elfes(3.0, -1e9, prior=lam), prior=lam)
    torch.testing.assert_close(fwd.marginals, elfes.probabilities, rtol=0, atol=1e-12)
    inv = online_patch_map(model, 1, sensor="inverse", p_match=0.8)
    mor = evidence_grid(model.rays, Moravec(math.log(4.0), -math.log(4.0)), prior=lam)
    torch.testing.assert_close(inv.marginals, mor.probabilities, rtol=0, atol=1e-12)
    # the README's condition: with the robot's cell pinned free (the default) Elfes's update, which does
    # not know it, differs by about 0.02 on the thesis toy
    pinned = online_patch_map(toy_model(lam=lam), 1).marginals[1:]
    gap = (pinned - elfes.probabilities[1:]).abs().max().item()
    assert 0.005 < gap < 0.05


@pytest.mark.parametrize("seed", range(4))
def test_offline_single_patch_is_exact(seed):
    rng = np.random.default_rng(seed)
    K = int(rng.integers(4, 11))
    z = np.clip(np.rint(rng.normal(K / 2, 1.5, int(rng.integers(1, 5)))), 0, K - 1)
    model = toy_model(K=K + 1, lam=float(rng.uniform(0.2, 0.7)), readings=z, sigma=1.5)
    exact = brute_force(model)
    for reference in ("map", torch.ones(K + 1)):  # the reference is irrelevant when one patch holds all
        pm = offline_patch_map(model, K, offset=1, reference=reference)
        torch.testing.assert_close(pm.marginals, exact.marginals, rtol=0, atol=1e-10)
        torch.testing.assert_close(pm.first_hit(0), exact.first_hit(0), rtol=0, atol=1e-10)
        assert pm.prob_free([1, 2]) == pytest.approx(exact.prob_free([1, 2]), abs=1e-10)


def test_first_hit_is_a_distribution_and_overlap_has_none():
    model = toy_model()
    for pm in (online_patch_map(model, 3, offset=1), offline_patch_map(model, 4)):
        fh = pm.first_hit(0)
        assert fh.sum().item() == pytest.approx(1.0, abs=1e-12) and (fh >= 0).all()
    with pytest.raises(ValueError, match="non-overlapping"):
        offline_patch_map(model, 3, overlap=True).first_hit(0)


def test_patch_maps_approach_exact_as_L_grows():
    """Averaged over datasets (Table 3.1's setting, fewer datasets): KL falls from L = 1 to L = 5 and the
    offline map beats the online one."""
    rng = np.random.default_rng(0)
    kl = {}
    for _ in range(40):
        z = np.clip(np.rint(rng.normal(20, 2, int(rng.integers(1, 9)))), 0, 30)
        toy = toy_1d(num_cells=31, wall=20, readings=z)
        model = OccupancyModel(toy.grid, raycast(toy.grid, toy.scans), GaussianRange(2.0), IndependentPrior(0.5, 31))
        exact = pose_constrained_1d(model).marginals[1:]
        for L in (1, 3, 5):
            for name, pm in (
                ("online", online_patch_map(model, L, offset=1)),
                ("offline", offline_patch_map(model, L, offset=1)),
                ("overlap", offline_patch_map(model, L, overlap=True)),
            ):
                q = pm.marginals[1:].clamp(1e-12, 1 - 1e-12)
                kl.setdefault((name, L), []).append(float(kl_divergence(exact, q)))
    mean = {k: np.mean(v) for k, v in kl.items()}
    for name in ("online", "offline", "overlap"):
        assert mean[(name, 5)] < mean[(name, 1)]
    for L in (1, 3, 5):
        assert mean[("offline", L)] < mean[("online", L)]
    assert mean[("overlap", 5)] < mean[("offline", 5)]


def test_2d_patch_maps_and_reference():
    ex = simple_2d_example(num_beams=180)
    model = OccupancyModel(
        ex.grid, raycast(ex.grid, ex.scans), GaussianRange(3.0), IndependentPrior(0.5, ex.grid.num_cells)
    )
    ref = reference_map(model)
    assert ref[~model.rays.reached()].all()  # unknown cells reflect the beam
    for shape in ((3, 3), "plus", (2, 5)):
        tiles = tile_patches(model, shape)
        assert sorted(tiles[tiles >= 0].tolist()) == model.latent.tolist()  # each latent cell in one tile
    assert online_patch_map(model, "plus").marginals.shape == (ex.grid.num_cells,)
    for pm in (
        online_patch_map(model, (3, 3)),
        offline_patch_map(model, (3, 3), reference=ref),
        offline_patch_map(model, "plus", overlap=True, reference=ref),
    ):
        p = pm.marginals
        assert torch.isfinite(p).all() and ((p >= 0) & (p <= 1)).all()
        assert p[model.known_free].sum() == 0


def test_bad_arguments():
    model = toy_model()
    with pytest.raises(ValueError, match="sensor"):
        online_patch_map(model, 3, sensor="sideways")
    with pytest.raises(ValueError, match="p_match"):
        online_patch_map(model, 3, sensor="inverse", p_match=1.0)
    with pytest.raises(ValueError, match="reference"):
        offline_patch_map(model, 3, reference=torch.zeros(5))
    with pytest.raises(ValueError, match="runs, rectangles"):
        online_patch_map(model, [[0, 0], [0, 2]])
    grid = Grid((3, 3))
    m2 = OccupancyModel(
        grid,
        raycast(grid, Scans([[0.5, 0.5, 0.0]], [0.0], [[1.5]], max_range=2.5)),
        GaussianRange(1.0),
        IndependentPrior(0.5, 9),
    )
    with pytest.raises(ValueError, match="at most 16"):
        offline_patch_map(m2, (3, 6))


def test_a_long_patch_map_shows_its_progress_and_time_left_and_blocks_change_nothing(monkeypatch):
    """The patches are weighed in blocks with progress between them (plain lines with the time left off a
    terminal): the same marginals and weights, bit for bit, as in one block."""
    import io

    from ogm_ppl.inference.patch_map import maps
    from ogm_ppl.inference.tiling import centred_patches
    from ogm_ppl.progress import Progress

    ex = simple_2d_example(num_beams=90)
    model = OccupancyModel(
        ex.grid, raycast(ex.grid, ex.scans), GaussianRange(3.0), IndependentPrior(0.5, ex.grid.num_cells)
    )
    ref = reference_map(model)
    whole_overlap = offline_patch_map(model, (2, 2), reference=ref, overlap=True)
    whole = offline_patch_map(model, (2, 2), reference=ref)
    online = online_patch_map(model, (2, 2))
    monkeypatch.setattr(maps, "_CONFIGURATIONS_PER_STEP", 16 * 64)  # 64 patches of 4 cells a block
    P = len(centred_patches(model, (2, 2))[0])
    out = io.StringIO()
    with Progress(P, "patch map", stream=out, every=0.0, bar=False) as bar:
        blocks = offline_patch_map(model, (2, 2), reference=ref, overlap=True, progress=bar)
    lines = out.getvalue().splitlines()
    assert lines[0] == f"patch map: 0/{P} (0 %), 0 s" and lines[-1].startswith(f"patch map: {P}/{P} (100 %)")
    assert len(lines) >= P // 64 and any(line.endswith(" left") for line in lines)
    assert torch.equal(blocks.marginals, whole_overlap.marginals)
    again = offline_patch_map(model, (2, 2), reference=ref)
    assert torch.equal(again.marginals, whole.marginals) and np.array_equal(again.log_weights, whole.log_weights)
    assert torch.equal(online_patch_map(model, (2, 2)).marginals, online.marginals)
