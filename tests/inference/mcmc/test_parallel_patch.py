"""Chromatic patch sweeps (:class:`~ogm_ppl.inference.mcmc.parallel.ChromaticPatchGibbs`,
:mod:`ogm_ppl.inference._kernels.parallel_patch`): the threaded sweep equals the serial composition of its patch
updates bit for bit, for any thread count (independent, MRF, patch-table, backed-off border priors; heat bath,
metropolised, Algorithm 2's random patch, the escape move); the first hits stay exact; the layout's rule; long
runs against brute-force marginals; bad settings refused."""

from __future__ import annotations

import numba
import numpy as np
import pytest
import torch

from ogm_ppl.inference._kernels import parallel as par
from ogm_ppl.inference._kernels import parallel_patch as pp
from ogm_ppl.inference._kernels.cells import first_hits
from ogm_ppl.inference._kernels.patch_state import patch_state
from ogm_ppl.inference._kernels.patch_sweep import patch_sweep
from ogm_ppl.inference.mcmc import PatchGibbs
from ogm_ppl.inference.mcmc.gibbs import _SCAN_CODES
from ogm_ppl.inference.mcmc.parallel import ChromaticPatchGibbs
from ogm_ppl.priors import MRFPrior, PatchTablePrior, prior_by_name
from tests.inference.mcmc.test_parallel import assert_long_run_matches_brute_force, scene, short_rays, sweep_seed

THREADS = min(2, numba.config.NUMBA_NUM_THREADS)
N = 30


def priors():
    return {
        "independent": None,
        "mrf": MRFPrior((N, N), order=1, psi=0.4, cell_prior=0.3),
        "patch_table": PatchTablePrior(
            (N, N), codes=[0, 0b000000111, 0b001001001, 0b111111111], counts=[6, 1, 1, 2], patch=(3, 3)
        ),
        "border_bo": prior_by_name("border_bo:generated", (N, N)),
    }


def reference_sweep(k, start: np.ndarray, seed: np.uint64) -> np.ndarray:
    """The same patch updates one group after another (tiles colour by colour, then the long patches) on a
    state of its own, through the serial patch kernel."""
    m = start.copy()
    f = first_hits(m, k._offsets, k._cells)
    ps = patch_state(m, f, k._index)
    lay = k.layout
    rows = 5 if k._escapes() else 3
    groups = [(int(t), lay.anchors[lay.tile_off[t] : lay.tile_off[t + 1]]) for t in lay.col_tiles]
    groups.append((lay.n_tiles, lay.long_anchors))
    for t, anchors in groups:
        a, u = pp.patch_draws(anchors, _SCAN_CODES[k.scan], np.uint64(par.tile_seed(seed, t)), rows)
        patch_sweep(ps, k._geometry(), a, k._compiled, u, k._patch_rule())
    return m


#: (prior, scan, update, p_rand_patch, patch, tile, longest reading in cells): tiles a little shorter than the
#: longest rays, so that most patches are short and some long
CASES = [
    ("independent", "systematic", "gibbs", 0.0, (3, 3), 3, 3.5),
    ("mrf", "permutation", "metropolised", 0.0, (2, 2), 4, 4.5),
    ("mrf", "systematic", "gibbs", 0.3, "plus", 4, 4.5),
    ("patch_table", "systematic", "gibbs", 0.0, (3, 3), 3, 3.5),
    ("border_bo", "permutation", "gibbs", 0.0, (3, 3), 6, 7.0),
]


@pytest.mark.parametrize("name, scan, update, p_rand, patch, tile, rmax", CASES)
def test_threaded_patch_sweep_is_the_serial_composition_for_any_thread_count(
    name, scan, update, p_rand, patch, tile, rmax
):
    model = scene(n=N, rmax=rmax, prior=priors()[name])
    runs = []
    for threads in sorted({1, THREADS}):
        kw = {"offset": model.prior.origin} if name in ("patch_table", "border_bo") else {}
        k = ChromaticPatchGibbs(
            model, patch, scan=scan, update=update, p_rand_patch=p_rand, tile=tile, threads=threads, **kw
        )
        torch.manual_seed(11)
        k.setup()
        lay = k.layout
        assert np.diff(lay.col_off).min() >= 4 and len(lay.long_anchors) > 0, "both phases are exercised"
        assert len(lay.anchors) >= 16
        start = k.state.copy()
        ref = reference_sweep(k, start, sweep_seed(5))
        torch.manual_seed(5)
        p = k.sample(k.current_params())
        assert np.array_equal(k.state, ref), "one threaded sweep differs from its serial composition"
        assert not np.array_equal(k.state, start)
        for _ in range(5):
            p = k.sample(p)
        assert np.array_equal(k.first_hit_state, first_hits(k.state, k._offsets, k._cells)), "first hits out of step"
        runs.append(k.state.copy())
    assert all(np.array_equal(runs[0], x) for x in runs)


def test_every_patch_is_in_one_group_and_short_patches_in_one_tile():
    model = scene(n=N, rmax=4.0, prior=priors()["border_bo"])
    k = ChromaticPatchGibbs(model, (3, 3), offset=model.prior.origin, tile=6)
    lay = k.layout
    both = np.concatenate([lay.anchors, lay.long_anchors])
    assert sorted(map(tuple, both)) == sorted(map(tuple, k._anchors))
    T, (o_r, o_c) = lay.T, (lay.o_r, lay.o_c)
    for t in lay.col_tiles:
        for a in lay.anchors[lay.tile_off[t] : lay.tile_off[t + 1]]:
            r0, c0 = (a[0] - o_r) // T, (a[1] - o_c) // T
            r1, c1 = (a[0] + 2 - o_r) // T, (a[1] + 2 - o_c) // T
            assert (r0, c0) == (r1, c1) and r0 * lay.n_tc + c0 == t
    assert par.colour_of_tile(lay.col_tiles, lay.n_tc).tolist() == sorted(
        par.colour_of_tile(lay.col_tiles, lay.n_tc).tolist()
    )


def test_long_runs_match_the_exact_marginals():
    """2 x 5 short-ray problem, 1 x 2 patches on 2 x 2 tiles (two tiles of one colour per phase), MRF prior:
    every marginal of a 3000-sweep chain within 5 batch-means standard errors (20 batches) of the exact one."""
    model = short_rays(prior=MRFPrior((2, 5), order=1, psi=0.4, cell_prior=0.4))
    k = ChromaticPatchGibbs(model, (1, 2), tile=2, threads=1)
    assert np.diff(k.layout.col_off).max() >= 2
    assert_long_run_matches_brute_force(k, 3000)


def test_bad_settings_are_refused():
    model = scene(n=12)
    with pytest.raises(ValueError, match="systematic' or 'permutation"):
        ChromaticPatchGibbs(model, (3, 3), scan="random")
    with pytest.raises(ValueError, match="multiple of the patch"):
        _ = ChromaticPatchGibbs(model, (3, 3), tile=4).layout
    with pytest.raises(ValueError, match="positive"):
        ChromaticPatchGibbs(model, (3, 3), tile=0)
    with pytest.raises(ValueError, match="threads must lie"):
        ChromaticPatchGibbs(model, (3, 3), threads=10_000)
    field = scene(n=12, prior=prior_by_name("border_bo:generated", (12, 12)))
    with pytest.raises(ValueError, match="factor extent"):
        _ = ChromaticPatchGibbs(field, (3, 3), offset=field.prior.origin, tile=3).layout


def test_unobserved_tiles_draw_from_the_shared_table_as_the_full_weighing_does():
    """A patch-table prior (no border) on a map most of whose tiles no ray reaches: the sweep draws those
    tiles from each segment's table once built (``shared_weights_key``); one sweep equals, bit for bit, heat
    bath draws from every patch's full weights (``patch_log_weights``: all ``2^9`` configurations, prior and
    likelihood) with the same uniforms (a table counting every configuration, so no patch is without mass; the
    observed patches, with all 512 candidates, take the dense likelihood path)."""
    from ogm_ppl.inference._kernels.choice import categorical

    counts = np.random.default_rng(0).integers(1, 50, 512)
    prior = PatchTablePrior((N, N), codes=np.arange(512), counts=counts, patch=(3, 3))
    model = scene(n=N, poses=3, beams=6, rmax=3.0, prior=prior)
    k = PatchGibbs(model, (3, 3), offset=prior.origin)
    torch.manual_seed(2)
    k.setup()
    reached = np.zeros(model.num_cells, bool)
    reached[model.ray_index().cells] = True
    pc = [p for p in k.patches()]
    unobserved = sum(not reached[p[p >= 0]].any() for p in pc)
    assert unobserved > len(pc) // 2
    ref = PatchGibbs(model, (3, 3), offset=prior.origin)
    ref.initial_params = k.initial_params
    ref.setup()
    torch.manual_seed(9)
    u = torch.rand(len(pc), dtype=torch.float64).numpy()
    torch.manual_seed(9)
    k.sample(k.current_params())
    ew = np.empty(512)
    for i, p in enumerate(pc):
        logw = ref.patch_log_weights(p)
        j = categorical(logw, len(logw), u[i], ew)
        m = ref.state.astype(np.float64)
        live = p[p >= 0]
        m[live] = (j >> np.arange(len(live))) & 1
        ref.set_state(torch.from_numpy(m))
    assert np.array_equal(k.state, ref.state)
