"""Every compiled kernel reproduces its recorded chains bit for bit.

Short chains from fixed seeds, for every kernel (:class:`CellGibbs`, :class:`MetropolisCell` with the
uniform and the endpoint proposal, :class:`PatchGibbs` with 1D runs, 2D rectangles, "plus" shapes,
tiles of table priors up to 5 x 5 and Algorithm 2's random patch in both modes), every scan, both update
rules, every prior route (independent cells, MRF and user stencils, patch tables, border-conditioned
tables, a prior with only ``log_prob``), with and without ``region=``; and ICM (:func:`map_estimate`) and
the patch maps. Each case's states (and cell / patch conditionals read at the end) are hashed (sha256)
and compared with ``chain_identity.json``. The probes hash float64 conditionals bit for bit, so a change in
the order in which a kernel sums the same terms changes their digests (not the states'). Regenerate only
for an intended change of the chains or of that rounding, having checked that the states are the same::

    PYTHONPATH=$PWD python tests/inference/mcmc/test_chain_identity.py --regen
"""

from __future__ import annotations

import hashlib
import json
import sys
from pathlib import Path

import numpy as np
import pytest
import torch

from ogm_ppl import GaussianRange, Grid, OccupancyModel, raycast
from ogm_ppl.datasets import simulate_scans, toy_1d
from ogm_ppl.inference.exact.map_estimate import map_estimate
from ogm_ppl.inference.mcmc.gibbs import CellGibbs, MetropolisCell, PatchGibbs
from ogm_ppl.inference.patch_map import offline_patch_map, online_patch_map
from ogm_ppl.priors import (
    BorderPatchPrior,
    IndependentPrior,
    MapPrior,
    MRFPrior,
    PatchTablePrior,
    StencilPrior,
)

FIXTURE = Path(__file__).with_name("chain_identity.json")
SWEEPS = 4
N2, N1 = 13, 24  # 2D side (not a multiple of 2, 3 or 5: tiles are cut by the edge), 1D length


class IsingLogProbOnly(MapPrior):
    """A pairwise field known only through ``log_prob``: the generic (Python) path."""

    def __init__(self, rows, cols, h=-0.6, J=0.8):
        self.rows, self.cols, self.h, self.J = rows, cols, h, J
        self.num_cells = rows * cols

    def log_prob(self, maps):
        m = torch.as_tensor(maps, dtype=torch.float64)
        g = m.reshape(*m.shape[:-1], self.rows, self.cols)
        pair = (g[..., :, 1:] * g[..., :, :-1]).sum((-1, -2)) + (g[..., 1:, :] * g[..., :-1, :]).sum((-1, -2))
        return self.h * m.sum(-1) + self.J * pair

    def sample(self, sample_shape=(), generator=None):
        shape = torch.Size(sample_shape) + (self.num_cells,)
        return (torch.rand(shape, generator=generator) < 0.5).to(torch.float64)


def _random_table(n_bits, n, seed, keep_zero=True):
    rng = np.random.default_rng(seed)
    codes = rng.integers(0, 1 << n_bits, n)
    if keep_zero:
        codes = np.r_[0, codes]
    return codes, rng.integers(1, 9, len(codes)).astype(float)


def _border_table(n_border, n_inner, n, seed):
    rng = np.random.default_rng(seed)
    b = rng.integers(0, 1 << n_border, n)
    i = rng.integers(0, 1 << n_inner, n)
    b = np.r_[b, 0, (1 << n_border) - 1]
    i = np.r_[i, 0, 0]
    return b, i, rng.integers(1, 9, len(b)).astype(float)


def priors_2d(shape):
    s = shape
    c3, n3 = _random_table(9, 120, 1)
    c5, n5 = _random_table(25, 300, 2)
    return {
        "indep": lambda: IndependentPrior(torch.linspace(0.2, 0.5, s[0] * s[1])),
        "mrf1": lambda: MRFPrior(s, order=1, psi=0.4, cell_prior=0.35),
        "mrf2": lambda: MRFPrior(s, order=2, psi=0.6, cell_prior=0.3),
        "stencil": lambda: StencilPrior(
            s,
            unary=np.linspace(-1.0, 0.2, s[0] * s[1]),
            offsets=[(0, 1), (1, 0), (1, 1)],
            coupling=[0.9, 0.7, -0.3],
            bias=0.1,
            outside=0.5,  # the recorded chains' occupancy beyond the grid edge
        ),
        "table3": lambda: PatchTablePrior(s, c3, n3, patch=(3, 3), origin=(1, 2)),
        "table5": lambda: PatchTablePrior(s, c5, n5, patch=(5, 5), origin=(2, 1)),
        "border3": lambda: BorderPatchPrior(s, *_border_table(16, 9, 2500, 3), inner=(3, 3)),
        "border2": lambda: BorderPatchPrior(s, *_border_table(12, 4, 1500, 4), inner=(2, 2), outside=0),
        "border2z": lambda: BorderPatchPrior(s, *_border_table(12, 4, 1500, 5), inner=(2, 2), unseen="zero"),
    }


def priors_1d(K):
    c3, n3 = _random_table(3, 6, 6)
    return {
        "indep": lambda: IndependentPrior(0.35, K),
        "mrf1": lambda: MRFPrior((K,), order=1, psi=0.4, cell_prior=0.3),
        "mrf2": lambda: MRFPrior((K,), order=2, psi=0.6, cell_prior=0.4),
        "table3": lambda: PatchTablePrior((K,), c3, n3, patch=3, origin=1),
        "border2": lambda: BorderPatchPrior((K,), *_border_table(2, 2, 12, 7), inner=2),
    }


def scene_2d(prior, n=N2):
    rng = np.random.default_rng(5)
    truth = np.zeros((n, n), bool)
    truth[0, :] = truth[-1, :] = truth[:, 0] = truth[:, -1] = True
    truth[n // 2 - 1, 1 : n - 3] = truth[1 : n - 2, n - 3] = True
    grid = Grid((n, n), resolution=0.1)
    free = np.argwhere(~truth)
    pick = free[rng.choice(len(free), 3, replace=False)]
    poses = np.c_[(pick[:, 1] + 0.5) * 0.1, (pick[:, 0] + 0.5) * 0.1, rng.uniform(-np.pi, np.pi, 3)]
    scans = simulate_scans(grid, truth, poses, np.arange(40) * (2 * np.pi / 40), 0.9, 1.0, 3)
    return OccupancyModel(grid, raycast(grid, scans), GaussianRange(1.0), prior)


def scene_1d(prior, K=N1):
    toy = toy_1d(num_cells=K, wall=15, readings=[15.0, 14.0, 16.0, 9.0, 15.0, 21.0])
    return OccupancyModel(toy.grid, raycast(toy.grid, toy.scans), GaussianRange(2.0), prior)


def _left_half(model):
    g = model.grid
    mask = np.zeros(g.shape, bool)
    mask[..., : max(1, g.shape[-1] // 2)] = True
    return mask


def cases() -> dict:
    """Case name -> a function returning the digest's input bytes (a chain, an ICM run, a patch map)."""
    out = {}
    P2, P1 = priors_2d((N2, N2)), priors_1d(N1)

    def chain(scene, prior, make, seed, region=False, probe=None):
        def run():
            model = scene(prior())
            torch.manual_seed(seed)
            kernel = make(model, _left_half(model) if region else None)
            kernel.setup()
            h = hashlib.sha256()
            params = kernel.initial_params
            h.update(np.ascontiguousarray(kernel.state).tobytes())
            for _ in range(SWEEPS):
                params = kernel.sample(params)
                h.update(np.ascontiguousarray(kernel.state).tobytes())
                h.update(np.ascontiguousarray(kernel.first_hit_state).tobytes())
            if probe is not None:
                h.update(probe(kernel, model))
            return h.hexdigest()

        return run

    def cell_probe(kernel, model):
        ks = model.latent.numpy()[:: max(1, len(model.latent) // 7)]
        return np.array([kernel.cell_log_odds(int(k)) for k in ks], np.float64).tobytes()

    def patch_probe(kernel, model):
        if kernel.L > 12:
            return b""
        pcs = kernel.patches()
        return b"".join(
            np.ascontiguousarray(kernel.patch_log_weights(p), np.float64).tobytes()
            for p in pcs[:: max(1, len(pcs) // 4)]
        )

    # single-cell Gibbs: every prior route, scan and update rule; region on some
    for pname, pf in {
        **{f"2d-{k}": (scene_2d, v) for k, v in P2.items()},
        **{f"1d-{k}": (scene_1d, v) for k, v in P1.items()},
    }.items():
        scene, prior = pf
        for scan in ("systematic", "permutation", "random"):
            for update in ("gibbs", "metropolised"):
                for region in (False, True):
                    if region and scan == "permutation":
                        continue
                    name = f"cell/{pname}/{scan}/{update}" + ("/region" if region else "")
                    out[name] = chain(
                        scene,
                        prior,
                        lambda m, r, s=scan, u=update: CellGibbs(m, scan=s, update=u, region=r),
                        seed=len(out),
                        region=region,
                        probe=cell_probe,
                    )
    small = lambda p: lambda: p((6, 6))
    for scan in ("systematic", "random"):
        for update in ("gibbs", "metropolised"):
            out[f"cell/generic/{scan}/{update}"] = chain(
                lambda pr: scene_2d(pr, n=6),
                small(lambda s: IsingLogProbOnly(*s)),
                lambda m, r, s=scan, u=update: CellGibbs(m, scan=s, update=u),
                seed=len(out),
                probe=cell_probe,
            )
    # Metropolis-Hastings flips
    for pname in ("indep", "mrf1", "border3"):
        for proposal, scan in (("uniform", "random"), ("uniform", "permutation"), ("endpoint", "random")):
            for region in (False, True):
                out[f"mh/2d-{pname}/{proposal}/{scan}" + ("/region" if region else "")] = chain(
                    scene_2d,
                    P2[pname],
                    lambda m, r, p=proposal, s=scan: MetropolisCell(m, proposal=p, scan=s, region=r),
                    seed=len(out),
                    region=region,
                )
    # patch Gibbs, 1D runs
    for pname, prior in P1.items():
        for scan in ("systematic", "permutation", "random"):
            for update in ("gibbs", "metropolised"):
                for prand, mode in ((0.0, "mh"), (0.3, "mh"), (0.3, "thesis")):
                    name = f"patch/1d-{pname}/run3/{scan}/{update}/p{prand}-{mode}"
                    out[name] = chain(
                        scene_1d,
                        prior,
                        lambda m, r, s=scan, u=update, p=prand, md=mode: PatchGibbs(
                            m, 3, scan=s, update=u, p_rand_patch=p, random_patch=md, offset=1
                        ),
                        seed=len(out),
                        probe=patch_probe,
                    )
        out[f"patch/1d-{pname}/run2/systematic/gibbs/region"] = chain(
            scene_1d, prior, lambda m, r: PatchGibbs(m, 2, region=r), seed=len(out), region=True, probe=patch_probe
        )
    # patch Gibbs, 2D shapes
    shapes = {
        "rect2x2": ((2, 2), (0, 0)),
        "rect1x3": ((1, 3), (0, 1)),
        "plus": ("plus", 0),
        "rect3x3": ((3, 3), (1, 2)),
    }
    for pname, prior in P2.items():
        for sname, (shape, offset) in shapes.items():
            if pname == "table3" and sname != "rect3x3":
                scans = ("systematic",)
            else:
                scans = ("systematic", "permutation", "random")
            for scan, update, prand, mode in (
                ("systematic", "gibbs", 0.0, "mh"),
                ("permutation", "metropolised", 0.0, "mh"),
                ("random", "gibbs", 0.25, "mh"),
                ("systematic", "gibbs", 0.25, "thesis"),
                ("random", "metropolised", 0.0, "mh"),
            ):
                if scan in scans:
                    name = f"patch/2d-{pname}/{sname}/{scan}/{update}/p{prand}-{mode}"
                    out[name] = chain(
                        scene_2d,
                        prior,
                        lambda m, r, sh=shape, o=offset, s=scan, u=update, p=prand, md=mode: PatchGibbs(
                            m, sh, scan=s, offset=o, update=u, p_rand_patch=p, random_patch=md
                        ),
                        seed=len(out),
                        probe=patch_probe,
                    )
            out[f"patch/2d-{pname}/{sname}/systematic/gibbs/region"] = chain(
                scene_2d,
                prior,
                lambda m, r, sh=shape, o=offset: PatchGibbs(m, sh, offset=o, region=r),
                seed=len(out),
                region=True,
                probe=patch_probe,
            )
    # tiles of table priors as patches, 5 x 5 included
    for pname, shape, origin in (("table5", (5, 5), (2, 1)), ("border3", (3, 3), (0, 0)), ("border2", (2, 2), (0, 0))):
        for scan in ("systematic", "permutation"):
            for update in ("gibbs", "metropolised"):
                for prand, mode in ((0.0, "mh"), (0.2, "mh"), (0.2, "thesis")):
                    name = f"tiles/2d-{pname}/{scan}/{update}/p{prand}-{mode}"
                    out[name] = chain(
                        scene_2d,
                        P2[pname],
                        lambda m, r, sh=shape, o=origin, s=scan, u=update, p=prand, md=mode: PatchGibbs(
                            m, sh, scan=s, offset=o, update=u, p_rand_patch=p, random_patch=md
                        ),
                        seed=len(out),
                        probe=patch_probe,
                    )
        out[f"tiles/2d-{pname}/systematic/gibbs/region"] = chain(
            scene_2d,
            P2[pname],
            lambda m, r, sh=shape, o=origin: PatchGibbs(m, sh, offset=o, region=r),
            seed=len(out),
            region=True,
            probe=patch_probe,
        )
    for scan in ("systematic", "random"):
        for update in ("gibbs", "metropolised"):
            for prand, mode in ((0.0, "mh"), (0.3, "mh"), (0.3, "thesis")):
                out[f"patch/generic/rect2x2/{scan}/{update}/p{prand}-{mode}"] = chain(
                    lambda pr: scene_2d(pr, n=6),
                    small(lambda s: IsingLogProbOnly(*s)),
                    lambda m, r, s=scan, u=update, p=prand, md=mode: PatchGibbs(
                        m, (2, 2), scan=s, update=u, p_rand_patch=p, random_patch=md
                    ),
                    seed=len(out),
                    probe=patch_probe,
                )

    # ICM
    def icm(scene, prior, init):
        def run():
            est = map_estimate(scene(prior()), init=init, seed=3)
            return hashlib.sha256(est.map.numpy().tobytes() + f"{est.sweeps}/{est.converged}".encode()).hexdigest()

        return run

    for pname, prior in P2.items():
        for init in ("occupied", "free", "random"):
            out[f"icm/2d-{pname}/{init}"] = icm(scene_2d, prior, init)
    for pname, prior in P1.items():
        out[f"icm/1d-{pname}/occupied"] = icm(scene_1d, prior, "occupied")
    out["icm/generic/random"] = icm(lambda pr: scene_2d(pr, n=6), small(lambda s: IsingLogProbOnly(*s)), "random")

    # patch maps (independent priors): deterministic sums of exponentials, whose last bits differ between CPUs
    # (the online forward weights' log-sum-exp), so they are hashed at 12 significant digits
    def _digits(x) -> bytes:
        return " ".join(f"{v:.11e}" for v in np.ravel(np.asarray(x, dtype=np.float64))).encode()

    def pmap(scene, fn):
        def run():
            pm = fn(scene(IndependentPrior(0.3, N2 * N2 if scene is scene_2d else N1)))
            h = hashlib.sha256(_digits(pm.marginals.numpy()))
            if pm.log_weights is not None:
                h.update(_digits(pm.log_weights))
            return h.hexdigest()

        return run

    for sname, scene, patch in (("2d", scene_2d, (2, 2)), ("1d", scene_1d, 3)):
        out[f"patchmap/{sname}/offline"] = pmap(scene, lambda m, p=patch: offline_patch_map(m, p))
        out[f"patchmap/{sname}/offline-overlap"] = pmap(scene, lambda m, p=patch: offline_patch_map(m, p, overlap=True))
        out[f"patchmap/{sname}/online-forward"] = pmap(scene, lambda m, p=patch: online_patch_map(m, p))
        out[f"patchmap/{sname}/online-inverse"] = pmap(
            scene, lambda m, p=patch: online_patch_map(m, p, sensor="inverse")
        )
    return out


CASES = cases()


def _expected() -> dict:
    return json.loads(FIXTURE.read_text())


def test_fixture_covers_every_case():
    assert sorted(_expected()) == sorted(CASES)


@pytest.mark.parametrize("name", sorted(CASES))
def test_chain_is_bit_identical(name):
    assert digest(name) == _expected()[name]


def digest(name: str) -> str:
    """The case's digest, computed under the test suite's settings (float64 default dtype)."""
    old = torch.get_default_dtype()
    torch.set_default_dtype(torch.float64)
    try:
        return CASES[name]()
    finally:
        torch.set_default_dtype(old)


def regenerate() -> None:
    from ogm_ppl.io import atomic_write_text

    digests = {name: digest(name) for name in sorted(CASES)}
    atomic_write_text(FIXTURE, json.dumps(digests, indent=1, sort_keys=True) + "\n")
    print(f"wrote {len(digests)} digests to {FIXTURE}")


if __name__ == "__main__":
    if sys.argv[1:] != ["--regen"]:
        raise SystemExit("usage: python tests/inference/mcmc/test_chain_identity.py --regen")
    regenerate()
