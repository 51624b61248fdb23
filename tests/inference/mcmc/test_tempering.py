"""Tempered bundles and models, and parallel tempering (ogm_ppl.inference.mcmc.tempering): exact checks on
enumerable problems (one PT step leaves the product of the tempered posteriors invariant, to 1e-12), the
kernel's draws against the exact one-step row, the cold chain's marginals, checkpoints and input checks."""

import math

import numpy as np
import pytest
import torch

from ogm_ppl.inference.exact import brute_force
from ogm_ppl.inference.mcmc import (
    CellGibbs,
    CheckpointError,
    KernelStateError,
    ParallelTempering,
    PatchGibbs,
    RunningStats,
    run_gibbs,
)
from ogm_ppl.inference.mcmc.diagnostics import ess
from ogm_ppl.inference.mcmc.tempering import TemperedPrior, check_ladder, geometric_ladder, tempered_model
from ogm_ppl.priors import BorderPatchPrior, IndependentPrior, MRFPrior, PatchTablePrior
from ogm_ppl.priors.compiled import patch_prior_batch
from ogm_ppl.testing import multinomial_goodness_of_fit
from ogm_ppl.testing.kernels import enumerable_1d, enumerate_maps, sweep_matrix


def _border_prior(num_cells: int, seed: int = 1) -> BorderPatchPrior:
    """A 1D border prior whose table has zeros (so some maps have no prior mass)."""
    rng = np.random.default_rng(seed)
    b, i = np.meshgrid(np.arange(4), np.arange(4), indexing="ij")
    counts = rng.integers(1, 6, b.shape).astype(float)
    counts[rng.random(b.shape) > 0.7] = 0
    return BorderPatchPrior((num_cells,), b.ravel(), i.ravel(), counts.ravel(), inner=2, outside=0)


PRIORS = {
    "independent": lambda K: IndependentPrior(torch.linspace(0.2, 0.6, K)),
    "mrf": lambda K: MRFPrior((K,), order=1, psi=0.2, cell_prior=0.4),
    "border": _border_prior,
}


def _model(prior: str, latent: int = 4):
    return enumerable_1d(latent, readings=(3.0, 2.0), prior=PRIORS[prior](latent + 1))


def _log_parts(model):
    """``log p~(S)`` and ``log L(S)`` of every enumerated map, from the untempered model."""
    S = enumerate_maps(model)
    return model.prior.log_prob(S).to(torch.float64), model.log_likelihood(S)


def _bundle_weights(bundle, K: int) -> np.ndarray:
    """``log p~(m) + const`` of all ``2^K`` maps through the compiled patch conditional of ``bundle``."""
    out = np.empty((1, 2**K), np.float64)
    patch_prior_batch(bundle, np.zeros((1, K), np.uint8), np.arange(K, dtype=np.int64), np.arange(2**K), out)
    return out[0]


# ---------------------------------------------------------------------------------------- tempered bundles
BUNDLE_PRIORS = {
    **{k: (lambda f: lambda: f(6))(f) for k, f in PRIORS.items()},
    "mrf 2d": lambda: MRFPrior((3, 3), order=2, psi=0.3, cell_prior=0.35),
    "patch table 2d": lambda: PatchTablePrior((2, 4), codes=[0, 3, 5, 15, 9], counts=[5, 2, 1, 1, 2], patch=(2, 2)),
}


@pytest.mark.parametrize("name", list(BUNDLE_PRIORS))
def test_tempered_bundle_scales_every_log_potential(name):
    prior = BUNDLE_PRIORS[name]()
    bundle = prior.compiled()
    K = prior.num_cells
    assert bundle.tempered(1.0) is bundle and bundle.tempered(1) is bundle
    base = _bundle_weights(bundle, K)
    ok = np.isfinite(base)
    ref = int(np.flatnonzero(ok)[0])
    for beta in (0.37, 2.5, 0.0):
        t = bundle.tempered(beta)
        assert type(t) is type(bundle)
        w = _bundle_weights(t, K)
        assert np.array_equal(np.isfinite(w), ok), "tempering must keep the support"
        np.testing.assert_allclose(w[ok] - w[ref], beta * (base[ok] - base[ref]), rtol=0, atol=1e-12)
    with pytest.raises(ValueError, match="beta"):
        bundle.tempered(-0.1)
    with pytest.raises(ValueError, match="beta"):
        bundle.tempered(float("nan"))


def test_tempered_prior_and_model():
    model = _model("border")
    assert tempered_model(model, 1.0, 1.0) is model
    lp, ll = _log_parts(model)
    S = enumerate_maps(model)
    for bp, bl in ((0.4, 1.0), (1.0, 0.3), (0.25, 0.6)):
        tm = tempered_model(model, bp, bl)
        assert tm.prior is model.prior if bp == 1 else isinstance(tm.prior, TemperedPrior)
        lj = tm.log_joint(S)
        expect = bp * lp + bl * ll
        assert torch.equal(torch.isfinite(lj), torch.isfinite(expect))
        ok = torch.isfinite(expect)
        torch.testing.assert_close(lj[ok], expect[ok], rtol=0, atol=1e-12)
    assert model.loglik_table is tempered_model(model, 0.5, 1.0).loglik_table  # the base model is untouched
    # beta = 0 keeps the supports: the tempered prior is uniform on the prior's support
    flat = TemperedPrior(model.prior, 0.0).log_prob(S)
    assert torch.equal(flat[torch.isfinite(lp)], torch.zeros(int(torch.isfinite(lp).sum()), dtype=torch.float64))
    assert (flat[~torch.isfinite(lp)] == -math.inf).all()
    with pytest.raises(ValueError, match="beta_lik"):
        tempered_model(model, 1.0, -1.0)


@pytest.mark.parametrize("kernel", ["cell", "patch"])
@pytest.mark.parametrize("prior", ["mrf", "border"])
def test_existing_kernels_sample_the_tempered_target_exactly(kernel, prior):
    model = _model(prior)
    tm = tempered_model(model, 0.3, 0.45)
    k = CellGibbs(tm) if kernel == "cell" else PatchGibbs(tm, 2)
    P = sweep_matrix(k)
    pi = torch.softmax(tm.log_joint(enumerate_maps(model)), 0)
    torch.testing.assert_close(P.sum(1), torch.ones(len(P), dtype=torch.float64), rtol=0, atol=1e-12)
    torch.testing.assert_close(pi @ P, pi, rtol=0, atol=1e-12)
    assert not torch.allclose(P, torch.eye(len(P), dtype=torch.float64))


# ---------------------------------------------------------------------------------------- the exact PT step
def _log_pis(pt, model):
    lp, ll = _log_parts(model)
    return [bp * lp + bl * ll for bp, bl in (pt.exponents(i) for i in range(pt.num_rungs))]


def _swap_op(D, i, logpi_i, logpi_j):
    """One swap move between rungs ``i, i + 1`` applied to a distribution ``D`` over product states."""
    new = logpi_i[None, :] + logpi_j[:, None]  # [a, b]: x_i = a, x_j = b swapped to x_i = b, x_j = a
    old = logpi_i[:, None] + logpi_j[None, :]
    A = torch.where(old > -math.inf, torch.exp(torch.clamp(new - old, max=0.0)), (new > -math.inf).double())
    A = torch.nan_to_num(A, nan=0.0)
    X = D.movedim((i, i + 1), (-2, -1))
    X = X * (1 - A) + X.transpose(-1, -2) * A.T
    return X.movedim((-2, -1), (i, i + 1))


def _pt_step(pt, model, D, parity: int):
    """The exact one-step operator of ``pt`` on a distribution ``D`` (``2^L`` per rung axis)."""
    for i, k in enumerate(pt.rungs):
        D = torch.tensordot(D, sweep_matrix(k), dims=([i], [0])).movedim(-1, i)
    lps = _log_pis(pt, model)
    n = pt.num_rungs - 1
    if pt.swaps == "random":
        return sum(_swap_op(D, i, lps[i], lps[i + 1]) for i in range(n)) / n
    pairs = range(n) if pt.swaps == "all" else range(parity, n, 2)
    for i in pairs:
        D = _swap_op(D, i, lps[i], lps[i + 1])
    return D


@pytest.mark.parametrize(
    "prior,kernel,temper,swaps",
    [
        ("mrf", "cell", "both", "all"),
        ("border", "cell", "prior", "even-odd"),
        ("border", "patch", "likelihood", "random"),
        ("mrf", "patch", "both", "even-odd"),
    ],
)
def test_one_pt_step_leaves_the_product_target_invariant(prior, kernel, temper, swaps):
    model = _model(prior)
    pt = ParallelTempering(model, (1.0, 0.5, 0.2), kernel=kernel, patch=2, temper=temper, swaps=swaps)
    pis = [torch.softmax(lp, 0) for lp in _log_pis(pt, model)]
    prod = torch.einsum("a,b,c->abc", *pis)
    for parity in (0, 1):
        out = _pt_step(pt, model, prod, parity)
        assert abs(float(out.sum()) - 1.0) < 1e-12
        assert float((out - prod).abs().max()) < 1e-12
    # the step moves, and the swaps do: a point mass spreads, and swapping differs from no swapping
    S = len(pis[0])
    point = torch.zeros((S, S, S), dtype=torch.float64)
    point[1, 6, 9] = 1.0
    assert float(_pt_step(pt, model, point, 0).max()) < 0.9


@pytest.mark.parametrize("swaps", ["all", "random"])
def test_pt_draws_follow_the_exact_one_step_row(swaps):
    model = _model("border")
    pt = ParallelTempering(model, (1.0, 0.3), kernel="cell", temper="both", swaps=swaps)
    S = enumerate_maps(model)
    start = (3, 12)
    n = len(S)
    point = torch.zeros((n, n), dtype=torch.float64)
    point[start] = 1.0
    row = _pt_step(pt, model, point, 0).reshape(-1)
    torch.manual_seed(0)
    counts = torch.zeros(n * n, dtype=torch.float64)
    weights = 1 << torch.arange(len(model.latent))
    for _ in range(2000):
        pt.set_rung_states(S[list(start)])
        pt.sample(pt.current_params())
        codes = (torch.from_numpy(pt.rung_states()[:, model.latent.numpy()]).long() * weights).sum(1)
        counts[int(codes[0]) * n + int(codes[1])] += 1
    assert counts[row <= 1e-15].sum() == 0
    big = row * 2000 >= 5
    p = torch.cat([row[big], row[~big].sum()[None]])
    c = torch.cat([counts[big], counts[~big].sum()[None]])
    if p[-1] == 0:  # nothing left to pool
        p, c = p[:-1], c[:-1]
    assert multinomial_goodness_of_fit(p / p.sum(), c, total_count=int(c.sum())) > 1e-3
    assert pt.swap_attempts.sum() > 0 and 0 < pt.swap_accepts.sum() < pt.swap_attempts.sum()


def test_cold_chain_marginals_match_brute_force():
    model = _model("mrf", latent=5)
    exact = brute_force(model).marginals[model.latent].numpy()
    pt = ParallelTempering(model, geometric_ladder(3, 0.2), kernel="cell", init="free")
    torch.manual_seed(1)
    pt.setup()
    params = pt.initial_params
    N = 4000
    trace = np.empty((N, len(model.latent)), np.float64)
    for t in range(N):
        params = pt.sample(params)
        trace[t] = params["m"].numpy()
    n_eff = ess(trace[None]).numpy()
    sd = np.sqrt(exact * (1 - exact) / n_eff)
    assert (np.abs(trace.mean(0) - exact) < 5 * sd + 1e-9).all(), (trace.mean(0), exact, sd)
    assert np.all(pt.swap_rates() > 0.05)


# ---------------------------------------------------------------------------------------- state and checks
def _run(pt, sweeps: int, seed: int) -> None:
    torch.manual_seed(seed)
    params = pt.current_params()
    for _ in range(sweeps):
        params = pt.sample(params)


def _flip(m: np.ndarray, k: int) -> np.ndarray:
    out = m.copy()
    out[k] = 1 - out[k]
    return out


def test_checkpoint_round_trip_and_reproducibility(tmp_path):
    model = _model("border")
    make = lambda: ParallelTempering(model, (1.0, 0.6, 0.3), kernel="patch", patch=2, init="free")
    a = make()
    a.setup()
    _run(a, 25, 3)
    path = tmp_path / "pt.npz"
    np.savez(path, **a.state_dict())
    with np.load(path, allow_pickle=False) as f:
        state = {k: f[k] for k in f.files}
    b = make()
    b.load_state_dict(state)
    assert np.array_equal(a.rung_states(), b.rung_states())
    _run(a, 30, 7)
    _run(b, 30, 7)
    assert np.array_equal(a.rung_states(), b.rung_states())
    assert np.array_equal(a.swap_attempts, b.swap_attempts) and np.array_equal(a.swap_accepts, b.swap_accepts)
    assert a.sweeps == b.sweeps == 55 and a.settings() == b.settings()
    c = make()  # the same seed from the same start: the same run
    c.setup()
    _run(c, 25, 3)
    _run(c, 30, 7)
    assert np.array_equal(a.rung_states(), c.rung_states())
    # bad states are refused, naming the entry
    other = ParallelTempering(model, (1.0, 0.5, 0.3), kernel="patch", patch=2)
    with pytest.raises(KernelStateError, match="betas"):
        other.load_state_dict(state)
    for key, value, what in (
        ("swap_accepts", np.array([99, 0]), "more accepted"),
        ("rung1.m", np.full(model.num_cells, 2, np.uint8), "rung 1"),
        ("m", _flip(state["m"], int(model.latent[0])), "cold rung"),
    ):
        bad = dict(state)
        bad[key] = value
        with pytest.raises(KernelStateError, match=what):
            make().load_state_dict(bad)
    bad = {k: v for k, v in state.items() if not k.startswith("rung2.")}
    with pytest.raises(KernelStateError, match="rung 2"):
        make().load_state_dict(bad)


@pytest.mark.parametrize(
    "betas,match",
    [
        ((), "non-empty"),
        ((1.0, 0.0), r"\(0, 1\]"),
        ((1.0, 1.5), r"\(0, 1\]"),
        ((1.0, float("nan")), r"\(0, 1\]"),
        ((0.8, 0.4), "betas\\[0\\] must be 1"),
        ((1.0, 0.3, 0.5), "strictly decreasing"),
        ((1.0, 1.0), "strictly decreasing"),
        (0.5, "1D"),
    ],
)
def test_bad_ladders_are_refused(betas, match):
    with pytest.raises(ValueError, match=match):
        check_ladder(betas)
    with pytest.raises(ValueError, match=match):
        ParallelTempering(_model("independent"), betas)


def test_ladder_and_options():
    lad = geometric_ladder(4, 0.125)
    np.testing.assert_allclose(lad, (1.0, 0.5, 0.25, 0.125), rtol=1e-15)
    assert geometric_ladder(1, 0.5) == (1.0,) and check_ladder(lad) == lad
    for bad in ((0, 0.5), (3, 1.0), (3, 0.0)):
        with pytest.raises(ValueError):
            geometric_ladder(*bad)
    model = _model("independent")
    for kw, match in (({"kernel": "guided"}, "kernel"), ({"temper": "all"}, "temper"), ({"swaps": "x"}, "swaps")):
        with pytest.raises(ValueError, match=match):
            ParallelTempering(model, (1.0, 0.5), **kw)
    pt = ParallelTempering(model, (1.0, 0.5))
    with pytest.raises(ValueError, match="one map per rung"):
        pt.set_rung_states(torch.zeros(3, model.num_cells))


def test_run_gibbs_resumes_a_tempering_run_bit_for_bit(tmp_path):
    model = _model("mrf")
    make = lambda: ParallelTempering(model, (1.0, 0.5, 0.25), swaps="random")
    whole = run_gibbs(make(), 60, RunningStats(model), seed=2, progress=False)
    ck = tmp_path / "pt.npz"
    part = run_gibbs(
        make(), 60, RunningStats(model), seed=2, checkpoint=ck, checkpoint_every=10, stop_after=25, progress=False
    )
    assert part.interrupted
    rest = run_gibbs(make(), 60, RunningStats(model), seed=2, checkpoint=ck, progress=False)
    assert np.array_equal(rest.state, whole.state)
    torch.testing.assert_close(rest.stats.marginals, whole.stats.marginals, rtol=0, atol=0)
    with pytest.raises(CheckpointError, match="kernel"):
        run_gibbs(
            ParallelTempering(model, (1.0, 0.4, 0.25), swaps="random"),
            60,
            RunningStats(model),
            seed=2,
            checkpoint=ck,
            progress=False,
        )


def test_pyro_mcmc_and_region():
    from pyro.infer import MCMC

    model = _model("mrf", latent=5)
    mcmc = MCMC(ParallelTempering(model, (1.0, 0.5)), num_samples=20, warmup_steps=3, disable_progbar=True)
    mcmc.run()
    assert mcmc.get_samples()["m"].shape == (20, len(model.latent))
    region = model.latent.numpy()[:2]
    start = torch.ones(model.num_cells, dtype=torch.float64)
    start[model.known_free] = 0
    pt = ParallelTempering(model, (1.0, 0.4), region=region, init=start)
    pt.setup()
    _run(pt, 40, 0)
    outside = np.setdiff1d(model.latent.numpy(), pt.sampled_cells())
    assert len(outside) and (pt.rung_states()[:, outside] == 1).all()
    assert np.array_equal(pt.sampled_cells(), region)
