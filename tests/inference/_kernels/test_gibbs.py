"""The ray terms of a patch update (:func:`collect_rays`, :func:`lik_list`, :func:`lik_grouped`) against a
from-scratch sum over every ray, :func:`lik_list` bit for bit against the per-candidate reading of the
entries, and :func:`lik_grouped` against it to rounding."""

from __future__ import annotations

import math

import numpy as np
import pytest

from ogm_ppl import GaussianRange, Grid, OccupancyModel, Scans, raycast
from ogm_ppl.inference._kernels.patch_lik import lik_grouped, lik_list
from ogm_ppl.inference._kernels.patch_rays import collect_rays, ray_scratch
from ogm_ppl.inference._kernels.patch_state import build_patch_at, set_patch
from ogm_ppl.inference.mcmc.gibbs import PatchGibbs
from ogm_ppl.priors import IndependentPrior


def scene(seed):
    """A 6 x 7 grid seen by eight poses (rays cross many 3 x 3 patches, some blocked before them)."""
    rng = np.random.default_rng(seed)
    grid = Grid((6, 7), resolution=1.0)
    poses = np.c_[rng.uniform(0.2, 6.8, 8), rng.uniform(0.2, 5.8, 8), rng.uniform(-math.pi, math.pi, 8)]
    angles = np.linspace(-1.2, 1.2, 9)
    ranges = rng.uniform(0.5, 6.0, (8, 9))
    scans = Scans(poses.tolist(), angles.tolist(), ranges.tolist(), max_range=6.0, over_range="max")
    return OccupancyModel(grid, raycast(grid, scans), GaussianRange(0.7), IndependentPrior(0.3, 42))


def first_hits(m, offsets, cells):
    """Every ray's first occupied kappa (its length if none), from scratch."""
    out = np.empty(len(offsets) - 1, np.int64)
    for r in range(len(out)):
        occ = np.flatnonzero(m[cells[offsets[r] : offsets[r + 1]]])
        out[r] = occ[0] if len(occ) else offsets[r + 1] - offsets[r]
    return out


def reference_lik_list(sc, ns, ll, cands, n, out):
    """The per-candidate reading: the first entry in kappa order whose bit the candidate sets."""
    for s in range(ns):
        r = sc.slot_ray[s]
        for j in range(n):
            if out[j] == -np.inf:
                continue
            fw = sc.slot_fout[s]
            for e in range(sc.slot_n[s]):
                if (int(cands[j]) >> int(sc.ent_bit[s, e])) & 1:
                    fw = sc.ent_kappa[s, e]
                    break
            out[j] += ll[r, fw]


@pytest.mark.parametrize("seed", [0, 1])
def test_ray_terms_of_every_configuration_match_the_sum_over_all_rays(seed):
    model = scene(seed)
    k = PatchGibbs(model, (3, 3), offset=(seed % 3, (seed + 1) % 3))
    k.setup(seed)
    ps, geo = k._ps, k._geometry()
    rng = np.random.default_rng(seed)
    ps.m[:] = (rng.random(len(ps.m)) < 0.35) & (geo.pinned == 0)
    ps.f[:] = first_hits(ps.m, ps.offsets, ps.cells)
    R = len(ps.f)
    rows = np.arange(R)
    patch = np.empty(9, np.int64)
    checked = 0
    for r0 in range(-2, geo.rows):
        for c0 in range(-2, geo.cols):
            L = build_patch_at(geo, r0, c0, patch)
            if L == 0:
                continue
            W = 1 << L
            cands = np.arange(W, dtype=np.int64)
            sc = ray_scratch(9, R, False, W)
            stamp = ps.stamp[0]
            ps.stamp[0] += 1
            ns = collect_rays(ps, patch, stamp, sc)
            assert not ps.in_patch.any()
            got = np.zeros(W)
            lik_list(sc, ns, ps.ll, cands, W, got)
            ref = np.zeros(W)
            reference_lik_list(sc, ns, ps.ll, cands, W, ref)
            np.testing.assert_array_equal(got, ref)  # the same sums, bit for bit
            grouped = np.zeros(W)
            assert lik_grouped(sc, ns, ps.ll, cands, W, grouped)
            assert (sc.g_of == -1).all()  # left clean for the next patch
            np.testing.assert_array_equal(np.isneginf(grouped), np.isneginf(ref))
            fin = np.isfinite(ref)
            np.testing.assert_allclose(grouped[fin], ref[fin], rtol=1e-13, atol=1e-12)  # other order, same terms
            for step in (3, 7):  # fewer candidates: the groups fold into smaller tables
                some = cands[::step].copy()
                part = np.zeros(len(some))
                assert lik_grouped(sc, ns, ps.ll, some, len(some), part)
                np.testing.assert_array_equal(np.isneginf(part), np.isneginf(ref[::step]))
                f = np.isfinite(ref[::step])
                np.testing.assert_allclose(part[f], ref[::step][f], rtol=1e-13, atol=1e-12)
            m0, f0 = ps.m.copy(), ps.f.copy()
            F = np.empty((W, R), np.int64)
            for w in range(W):
                set_patch(ps, patch, w)
                F[w] = ps.f
                np.testing.assert_array_equal(ps.f, first_hits(ps.m, ps.offsets, ps.cells))
            ps.m[:], ps.f[:] = m0, f0
            varies = (F != F[0]).any(0)  # the rays a configuration can change: exactly the slots kept
            assert varies.sum() == ns
            np.testing.assert_array_equal(np.sort(sc.slot_ray[:ns]), np.flatnonzero(varies))
            brute = ps.ll[rows[varies], F[:, varies]].sum(1)
            np.testing.assert_array_equal(np.isneginf(got), np.isneginf(brute))
            fin = np.isfinite(brute)
            np.testing.assert_allclose(got[fin], brute[fin], rtol=0, atol=1e-9)
            checked += ns > 0
    assert checked > 10


def collected_patches(seed):
    """``(ps, L, sc, ns)`` for each 3 x 3 tile of ``scene(seed)``, its rays collected into ``sc``."""
    k = PatchGibbs(scene(seed), (3, 3))
    k.setup(0)
    ps, geo = k._ps, k._geometry()
    patch = np.empty(9, np.int64)
    for a in k._anchors:
        L = build_patch_at(geo, int(a[0]), int(a[1]), patch)
        sc = ray_scratch(9, len(ps.f), False, 1 << L)
        stamp = ps.stamp[0]
        ps.stamp[0] += 1
        yield ps, L, sc, collect_rays(ps, patch, stamp, sc)


def test_candidates_already_impossible_stay_impossible():
    for ps, L, sc, ns in collected_patches(3):
        if ns == 0:
            continue
        cands = np.arange(1 << L, dtype=np.int64)
        out = np.zeros(1 << L)
        out[::2] = -np.inf
        ref = out.copy()
        grouped = out.copy()
        lik_list(sc, ns, ps.ll, cands, 1 << L, out)
        reference_lik_list(sc, ns, ps.ll, cands, 1 << L, ref)
        assert np.isneginf(out[::2]).all() and not np.isneginf(out[1::2]).all()
        np.testing.assert_array_equal(out, ref)
        assert lik_grouped(sc, ns, ps.ll, cands, 1 << L, grouped)
        np.testing.assert_array_equal(np.isneginf(grouped), np.isneginf(ref))
        return
    pytest.fail("no patch with rays")


def test_grouped_terms_decline_without_tables_or_beyond_their_groups():
    """Patches of more than GROUP_BITS cells have no tables, and rays with more cell masks than the
    scratch holds are declined: False, nothing added, the mask map left clean (the caller reads the slots
    one by one instead)."""
    for ps, L, sc, ns in collected_patches(4):
        masks = {int(np.bitwise_or.reduce(1 << sc.ent_bit[s, : sc.slot_n[s]])) for s in range(ns)}
        if len(masks) < 2:
            continue
        cands = np.arange(1 << L, dtype=np.int64)
        out = np.zeros(1 << L)
        one_group = sc._replace(g_mask=np.empty(1, np.int64), g_tab=np.empty((1, sc.g_tab.shape[1])))
        assert not lik_grouped(one_group, ns, ps.ll, cands, 1 << L, out)
        assert (out == 0).all() and (sc.g_of == -1).all()
        assert not lik_grouped(ray_scratch(11, len(ps.f), False, 1 << L), 0, ps.ll, cands, 1 << L, out)
        assert lik_grouped(sc, ns, ps.ll, cands, 1 << L, out)
        return
    pytest.fail("no patch whose rays have two masks")
