r"""The contract of a map kernel (:class:`~ogm_ppl.inference.mcmc.kernel.MapKernel`), as a pytest mixin.

A kernel's test class subclasses :class:`KernelContract` and writes one factory::

    class TestMyKernel(KernelContract):
        def make_kernel(self, model, region=None):
            return MyKernel(model, region=region)

and gets, on enumerable problems (``2^L`` maps; exact posterior by :func:`~ogm_ppl.inference.exact.brute_force`):

* **stationarity** of ``pi = p(m | z)`` in 1D and 2D: where :func:`sweep_matrix` knows the kernel, the exact
  one-sweep transition matrix ``P`` over all maps (rows sum to 1, ``pi P = pi`` to ``1e-10``, ``P`` moves),
  and the kernel's own sweeps from the posterior mode follow ``P``'s row (chi-square,
  ``multinomial_goodness_of_fit``); always, ``num_draws`` one-sweep chains started from exact posterior
  draws end distributed as ``pi`` (chi-square; bins of expected count < 5 pooled);
* ``setup()`` **restarts the chain**: set up again from one seed, it repeats the chain of a new kernel;
* the **checkpoint round trip**: ``state_dict`` through ``np.savez`` / ``np.load(allow_pickle=False)``
  into a new kernel continues the chain bit for bit, and bad states are refused with
  :class:`~ogm_ppl.inference.mcmc.kernel.KernelStateError`;
* ``region=``: the chain's cells outside ``sampled_cells()`` never change, and the conditional
  ``p(m_R' | m_rest, z)`` is stationary (exactly, where ``P`` is known; else by the draws test);
* a **long run** (``num_sweeps_long`` sweeps after ``num_sweeps_long // 20`` of warm-up) on the 1D, the 2D
  and a 3 x 4 problem whose rays cross from four directions reaches the exact marginals: every cell within
  ``z_long`` standard errors, the larger of the batch-means error (20 batches) and the error of as many
  independent draws; the pinned cells stay free at every sweep, and the kernel counts at least as many
  updates as changes. This is what catches a biased kernel that the one-sweep checks, started from the
  posterior, are too weak to see (an acceptance ratio a little off, an asymmetric proposal, a likelihood
  that misses rays). Where the exact sweep matrix is known and relaxes in more than ``num_sweeps_long / 100``
  sweeps (``1 / (1 - |lambda_2|)``: an exact kernel that mixes too slowly on that problem) it is skipped.

Seeds are fixed; p-values must exceed ``1e-3``.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from ogm_ppl.inference.exact import brute_force
from ogm_ppl.inference.mcmc.kernel import KernelStateError
from ogm_ppl.inference.tiling import patch_cells
from ogm_ppl.testing._stats import check_draws as _check_draws

__all__ = ["KernelContract", "enumerable_1d", "enumerable_2d", "enumerate_maps", "sweep_matrix"]


def enumerate_maps(model) -> torch.Tensor:
    """All ``2^L`` maps (``2^L x K`` float64), map ``i`` with latent cell ``j`` = bit ``j`` of ``i``
    (the order of ``brute_force(model).log_probs``)."""
    L = len(model.latent)
    maps = torch.zeros(2**L, model.num_cells, dtype=torch.float64)
    maps[:, model.latent] = ((torch.arange(2**L)[:, None] >> torch.arange(L)) & 1).double()
    return maps


def _codes(model, maps: torch.Tensor) -> torch.Tensor:
    bits = maps[..., model.latent].long()
    return (bits << torch.arange(len(model.latent))).sum(-1)


def _cell_matrix(kernel, k: int, rule: str, rows: torch.Tensor) -> torch.Tensor:
    """One update of cell ``k`` (heat bath or metropolised flip) from each map in ``rows``."""
    model = kernel.model
    S = enumerate_maps(model)
    T = torch.zeros(len(S), len(S), dtype=torch.float64)
    for i in rows.tolist():
        s = S[i]
        kernel.set_state(s)
        lo = kernel.cell_log_odds(int(k))
        t = s.clone()
        t[k] = 1 - s[k]
        j = int(_codes(model, t))
        if lo != lo:  # a map without mass: heat bath stays, metropolised flips a fair coin
            p = 0.0 if rule == "gibbs" else 0.5
        elif rule == "gibbs":
            p1 = 1.0 if lo == math.inf else 0.0 if lo == -math.inf else 1 / (1 + math.exp(-lo))
            p = p1 if s[k] == 0 else 1 - p1
        else:
            d = -lo if s[k] else lo
            p = 1.0 if d >= 0 else (math.exp(d) if d > -math.inf else 0.0)
        T[i, j] += p
        T[i, i] += 1 - p
    return T


def _patch_matrix(kernel, patch: np.ndarray, rows: torch.Tensor) -> torch.Tensor:
    """One update of ``patch`` (Gibbs or metropolised; with probability ``p_rand_patch`` a uniform
    configuration accepted by Metropolis-Hastings, or always with ``random_patch="thesis"``)."""
    model = kernel.model
    S = enumerate_maps(model)
    T = torch.zeros(len(S), len(S), dtype=torch.float64)
    live = patch[patch >= 0]
    p_rand = kernel.p_rand_patch
    for i in rows.tolist():
        s = S[i]
        if len(live) == 0:
            T[i, i] = 1.0
            continue
        kernel.set_state(s)
        logw = torch.from_numpy(np.asarray(kernel.patch_log_weights(patch), dtype=np.float64))
        W = len(logw)
        if not torch.isfinite(logw).any():
            T[i, i] = 1.0
            continue
        cur = int(sum(int(s[c]) << j for j, c in enumerate(live)))
        p = torch.softmax(logw, 0)
        if kernel.update == "metropolised":
            rest = 1.0 - float(p[cur])
            g = torch.zeros(W, dtype=torch.float64)
            for w in range(W):
                if w != cur and rest > 0:
                    g[w] = p[w] / rest * min(1.0, rest / (1.0 - float(p[w]))) if p[w] < 1 else 1.0
            g[cur] = 1.0 - (g.sum() - g[cur])
        else:
            g = p
        mh = torch.zeros(W, dtype=torch.float64)
        for w in range(W):
            a = 1.0 if kernel.thesis_random else min(1.0, float(torch.exp(logw[w] - logw[cur])))
            mh[w] += a / W
            mh[cur] += (1 - a) / W
        row = (1 - p_rand) * g + p_rand * mh
        for w in range(W):
            t = s.clone()
            t[torch.from_numpy(live)] = torch.tensor([(w >> j) & 1 for j in range(len(live))], dtype=torch.float64)
            T[i, int(_codes(model, t))] += row[w]
    return T


def _block_matrix(kernel, cells: np.ndarray, rows: torch.Tensor) -> torch.Tensor:
    """One guide move on block ``cells``: propose ``c ~ q_B``, accept by the kernel's ``log_ratios``."""
    model = kernel.model
    S = enumerate_maps(model)
    L = len(cells)
    configs = ((np.arange(2**L)[:, None] >> np.arange(L)) & 1).astype(np.float64)
    q = np.exp(kernel.proposal_log_prob(torch.from_numpy(cells), torch.from_numpy(configs)).numpy())
    T = torch.zeros(len(S), len(S), dtype=torch.float64)
    for i in rows.tolist():
        s = S[i].numpy()
        acc = np.exp(np.minimum(kernel.log_ratios(s, cells, configs), 0.0))
        to = np.repeat(s[None, :], len(configs), 0)
        to[:, cells] = configs
        for j, pj in zip(_codes(model, torch.from_numpy(to)).tolist(), q * acc):
            if j != i:
                T[i, j] += float(pj)
        T[i, i] = 1.0 - T[i].sum()
    return T


def _average_over_orders(mats: list[torch.Tensor]) -> torch.Tensor:
    """The mean over all orders of the product of ``mats`` (a fresh random permutation each sweep),
    by dynamic programming over subsets: ``A(U) = mean_{k in U} A(U - k) T_k``."""
    n = len(mats)
    A = {0: torch.eye(len(mats[0]), dtype=torch.float64)}
    for mask in range(1, 1 << n):
        ks = [k for k in range(n) if mask >> k & 1]
        A[mask] = sum(A[mask ^ (1 << k)] @ mats[k] for k in ks) / len(ks)
    return A[(1 << n) - 1]


def _scan(mats: list[torch.Tensor], scan: str, weights=None, n: int | None = None) -> torch.Tensor | None:
    if scan == "systematic":
        P = torch.eye(len(mats[0]), dtype=torch.float64)
        for T in mats:
            P = P @ T
        return P
    if scan == "permutation":
        return _average_over_orders(mats) if len(mats) <= 8 else None
    w = torch.full((len(mats),), 1 / len(mats), dtype=torch.float64) if weights is None else weights
    mean = sum(wi * T for wi, T in zip(w.tolist(), mats))
    return torch.linalg.matrix_power(mean, len(mats) if n is None else n)


def sweep_matrix(kernel, rows: torch.Tensor | None = None) -> torch.Tensor | None:
    """The exact one-sweep transition matrix of one of the library's kernels (``2^L x 2^L`` over
    :func:`enumerate_maps`), or ``None`` for a kernel it does not know. Only the ``rows`` (map indices;
    default: all) are filled, so a product leaving them loses mass (and fails a row-sum check)."""
    from ogm_ppl.inference.mcmc.cycle import KernelCycle, KernelMixture
    from ogm_ppl.inference.mcmc.gibbs import CellGibbs, MetropolisCell, PatchGibbs
    from ogm_ppl.inference.mcmc.guided import GuidedGibbs

    model = kernel.model
    rows = torch.arange(2 ** len(model.latent)) if rows is None else rows
    if isinstance(kernel, MetropolisCell):
        cells = kernel.sampled_cells()
        mats = [_cell_matrix(kernel, int(k), "metropolised", rows) for k in cells]
        if kernel.scan != "random":
            return _scan(mats, kernel.scan)
        q = kernel.proposal_probs()[torch.from_numpy(np.isin(model.latent.numpy(), cells))]
        return _scan(mats, "random", q / q.sum(), len(cells))
    if isinstance(kernel, CellGibbs):
        return _scan([_cell_matrix(kernel, int(k), kernel.update, rows) for k in kernel.sampled_cells()], kernel.scan)
    if isinstance(kernel, PatchGibbs):
        if kernel.scan != "random":
            return _scan([_patch_matrix(kernel, p, rows) for p in kernel.patches()], kernel.scan)
        pool = kernel.sampled_cells() if kernel.region is None else np.intersect1d(kernel.region, model.latent)
        g = model.grid
        anchors = np.stack(np.divmod(pool, g.cols), 1).astype(np.int64)
        mats = [_patch_matrix(kernel, p, rows) for p in patch_cells(model, anchors, kernel.dr, kernel.dc)]
        return _scan(mats, "random", None, math.ceil(len(pool) / kernel.L))
    if isinstance(kernel, KernelMixture):  # P = sum_i w_i P_i: one part drawn by weight
        parts = [sweep_matrix(k, rows) for k in kernel.kernels]
        w = torch.from_numpy(kernel.weights)
        return None if any(P is None for P in parts) else _scan(parts, "random", w, 1)  # type: ignore[arg-type]
    if isinstance(kernel, KernelCycle):  # P = P_1 P_2 ... P_n
        parts = [sweep_matrix(k, rows) for k in kernel.kernels]
        return None if any(P is None for P in parts) else _scan(parts, "systematic")  # type: ignore[arg-type]
    if isinstance(kernel, GuidedGibbs):
        offs = kernel.offsets()
        G = torch.zeros(2 ** len(model.latent), 2 ** len(model.latent), dtype=torch.float64)
        for off in offs:
            mats = [_block_matrix(kernel, cells, rows) for cells, _ in kernel.blocks(off)]
            P = _scan(mats, "systematic")
            assert P is not None
            G += P / len(offs)
        if kernel.p_guide >= 1.0:
            return G
        B = sweep_matrix(kernel.base, rows)
        return None if B is None else kernel.p_guide * G + (1 - kernel.p_guide) * B
    return None


def enumerable_1d(K: int = 6, readings=(3.0, 4.0, 2.0), sensor=None, prior=None):
    """A 1D toy of ``K + 1`` cells (robot in cell 0, ``K`` latent), ``GaussianRange(1.5)`` and a graded
    independent prior ``linspace(0.2, 0.6)`` unless given: small enough to enumerate its ``2^K`` maps."""
    from ogm_ppl import GaussianRange, OccupancyModel, raycast
    from ogm_ppl.datasets import toy_1d
    from ogm_ppl.priors import IndependentPrior

    toy = toy_1d(num_cells=K + 1, wall=1, readings=readings)
    prior = prior if prior is not None else IndependentPrior(torch.linspace(0.2, 0.6, K + 1))
    return OccupancyModel(toy.grid, raycast(toy.grid, toy.scans), sensor or GaussianRange(1.5), prior)


def enumerable_2d_data():
    """``(grid, scans)`` of :func:`enumerable_2d`: a 2 x 4 grid of 1 m cells and four readings (one robot in
    cell 0, two beams along the bottom row, one back along the top row, one up), max-range ones among them."""
    from ogm_ppl import Grid, Scans

    grid = Grid((2, 4), resolution=1.0)
    scans = Scans(
        [[0.5, 0.5, 0.0], [0.5, 0.5, 0.0], [3.5, 1.5, math.pi], [0.5, 0.5, math.pi / 2]],
        [0.0],
        [[2.2], [3.9], [1.4], [1.0]],
        max_range=3.9,
        over_range="max",
    )
    return grid, scans


def enumerable_2d(sensor=None, prior=None):
    """A 2 x 4 grid (7 latent cells) with four max-range-capable readings (:func:`enumerable_2d_data`),
    ``GaussianRange(0.9)`` unless given, and ``prior`` (default: a graded independent prior
    ``linspace(0.25, 0.55)``)."""
    from ogm_ppl import GaussianRange, OccupancyModel, raycast
    from ogm_ppl.priors import IndependentPrior

    grid, scans = enumerable_2d_data()
    prior = prior if prior is not None else IndependentPrior(torch.linspace(0.25, 0.55, 8))
    return OccupancyModel(grid, raycast(grid, scans), sensor or GaussianRange(0.9), prior)


class KernelContract:
    """Pytest mixin: a map kernel's contract (module docstring). Override :meth:`make_kernel`; optionally
    the problems, :meth:`transition_matrix`, ``supports_region`` and the sample sizes."""

    num_draws = 1000  #: chains / repeats for each statistical check
    num_sweeps_long = 8000  #: sweeps of the long-run check
    z_long = 4.5  #: its tolerance, in standard errors
    supports_region = True
    region = np.array([1, 2, 5, 6])  #: region of the 3 x 4 region problem

    def make_kernel(self, model, region=None):
        raise NotImplementedError

    def problem_1d(self):
        """An enumerable 1D problem (:func:`enumerable_1d`: 6 latent cells, graded independent prior)."""
        return enumerable_1d()

    def problem_2d(self):
        """An enumerable 2D problem (:func:`enumerable_2d`: 2 x 4 grid, 7 latent cells, max-range readings)."""
        return enumerable_2d()

    def problem_region(self):
        """A 3 x 4 grid (9 latent cells) for ``region=`` (:attr:`region`)."""
        from ogm_ppl import GaussianRange, Grid, OccupancyModel, Scans, raycast
        from ogm_ppl.priors import IndependentPrior

        grid = Grid((3, 4), resolution=1.0)
        poses = [
            [0.5, 0.5, 0.0],
            [0.5, 0.5, 0.0],
            [3.5, 2.5, math.pi],
            [0.5, 0.5, math.pi / 2],
            [1.5, 2.5, -math.pi / 2],
            [3.5, 2.5, -math.pi / 2],
        ]
        scans = Scans(
            np.array(poses),
            np.array([0.0]),
            np.array([[2.2], [3.9], [1.4], [2.1], [1.6], [1.2]]),
            max_range=3.9,
            over_range="max",
        )
        return OccupancyModel(
            grid, raycast(grid, scans), GaussianRange(0.9), IndependentPrior(torch.linspace(0.25, 0.55, 12))
        )

    def transition_matrix(self, kernel, rows=None) -> torch.Tensor | None:
        """The exact one-sweep matrix (``None``: unknown, only the statistical check runs)."""
        return sweep_matrix(kernel, rows)

    # ------------------------------------------------------------------ the checks
    def _one_sweeps(self, kernel, starts: torch.Tensor, seed: int) -> torch.Tensor:
        model = kernel.model
        torch.manual_seed(seed)
        out = torch.zeros(len(starts), dtype=torch.long)
        for i, s in enumerate(starts):
            kernel.set_state(s)
            out[i] = _codes(model, model.full_map(kernel.sample(kernel.current_params())["m"]))
        return out

    def _check_stationary(self, kernel, pi: torch.Tensor, what: str) -> None:
        model = kernel.model
        S = enumerate_maps(model)
        live = torch.nonzero(pi > 0).flatten()
        P = self.transition_matrix(kernel, live)
        n = self.num_draws
        if P is not None:
            Pl = P[live]
            assert (Pl >= -1e-15).all()
            torch.testing.assert_close(Pl.sum(1), torch.ones(len(live), dtype=torch.float64), rtol=0, atol=1e-10)
            torch.testing.assert_close(pi @ P, pi, rtol=0, atol=1e-10)
            assert (Pl - torch.eye(len(pi), dtype=torch.float64)[live]).abs().max() > 1e-3, f"{what}: P does not move"
            i0 = int(torch.argmax(pi))
            ends = self._one_sweeps(kernel, S[i0].expand(n, -1), seed=5)
            _check_draws(P[i0], torch.bincount(ends, minlength=len(pi)).double(), f"{what}: sweep row")
        g = torch.Generator().manual_seed(7)
        start = torch.multinomial(pi, n, replacement=True, generator=g)
        ends = self._one_sweeps(kernel, S[start], seed=6)
        assert (ends != start).double().mean() > 0.01, f"{what}: the chains do not move"
        _check_draws(pi, torch.bincount(ends, minlength=len(pi)).double(), f"{what}: pi-started sweeps")

    @pytest.mark.parametrize("dim", ["1d", "2d"])
    def test_contract_exact_posterior_is_stationary(self, dim):
        model = getattr(self, f"problem_{dim}")()
        assert len(model.latent) <= 10
        pi = brute_force(model).log_probs.exp()
        torch.testing.assert_close(pi, torch.softmax(model.log_joint(enumerate_maps(model)), 0), rtol=0, atol=1e-12)
        kernel = self.make_kernel(model)
        kernel.setup()
        self._check_stationary(kernel, pi, dim)

    def test_contract_setup_restarts_the_chain(self):
        """``setup()`` starts a chain afresh (``pyro.infer.MCMC`` calls it for each chain): from one seed, the
        same kernel set up again, and a new kernel, repeat the chain sweep for sweep."""
        model = self.problem_2d()
        traces = []
        for kernel in (a := self.make_kernel(model), a, self.make_kernel(model)):
            torch.manual_seed(4)
            kernel.setup()
            params, trace = kernel.current_params(), []
            for _ in range(15):
                params = kernel.sample(params)
                trace.append(kernel.state.copy())
            traces.append(np.stack(trace))
        assert np.array_equal(traces[0], traces[2]), "two kernels from one seed differ"
        assert np.array_equal(traces[0], traces[1]), "setup() again did not restart the chain"

    def test_contract_checkpoint_round_trip(self, tmp_path):
        model = self.problem_2d()
        a = self.make_kernel(model)
        torch.manual_seed(3)
        a.setup()
        params = a.current_params()
        for _ in range(7):
            params = a.sample(params)
        state = a.state_dict()
        np.savez(tmp_path / "k.npz", **state)
        with np.load(tmp_path / "k.npz", allow_pickle=False) as z:
            saved = {k: z[k] for k in z.files}
        b = self.make_kernel(model)
        b.load_state_dict(saved)
        assert np.array_equal(b.state, a.state)
        rng = torch.get_rng_state()
        pa = a.current_params()
        runs = []
        for k, p in ((a, pa), (b, b.current_params())):
            torch.set_rng_state(rng)
            trace = []
            for _ in range(12):
                p = k.sample(p)
                trace.append(k.state.copy())
            runs.append(np.stack(trace))
        assert np.array_equal(runs[0], runs[1])
        sa, sb = a.state_dict(), b.state_dict()
        assert sa.keys() == sb.keys() and all(np.array_equal(sa[k], sb[k]) for k in sa)
        bad = [
            ({k: v for k, v in state.items() if k != "sweeps"}, "lacks sweeps"),
            ({**state, "format": np.int64(99)}, "format 99"),
            ({**state, "kind": np.str_("Nothing")}, "Nothing"),
            ({**state, "m": state["m"][:-1]}, "shape"),
            ({**state, "m": np.full_like(state["m"], 2)}, "0/1"),
            ({**state, "updates": np.int64(-1)}, "updates"),
        ]
        for s, match in bad:
            with pytest.raises(KernelStateError, match=match):
                self.make_kernel(model).load_state_dict(s)

    @pytest.mark.parametrize("problem", ["1d", "2d", "crossing"])
    def test_contract_long_run_reaches_the_exact_marginals(self, problem):
        model = self.problem_region() if problem == "crossing" else getattr(self, f"problem_{problem}")()
        exact = brute_force(model).marginals.numpy()
        kernel = self.make_kernel(model)
        n = int(self.num_sweeps_long)
        torch.manual_seed(11)
        kernel.setup()
        params = kernel.current_params()
        for _ in range(n // 20):
            params = kernel.sample(params)
        pinned = model.known_free.numpy().astype(bool)
        trace = np.empty((n, model.num_cells), dtype=np.uint8)
        for i in range(n):
            params = kernel.sample(params)
            trace[i] = kernel.state
        bad = np.flatnonzero(trace[:, pinned].any(0))
        assert len(bad) == 0, f"{problem}: pinned cells {np.flatnonzero(pinned)[bad].tolist()} occupied"
        assert kernel.updates >= kernel.changes > 0, (kernel.updates, kernel.changes)
        mean = trace.mean(0)
        batches = trace[: n - n % 20].reshape(20, -1, model.num_cells).mean(1)
        se = np.maximum(batches.std(0, ddof=1) / math.sqrt(20), np.sqrt(exact * (1 - exact) / n))
        z = np.abs(mean - exact) / np.maximum(se, 1e-12)
        worst = int(np.argmax(z))
        if z[worst] > self.z_long:
            P = self.transition_matrix(kernel)
            if P is not None:  # an exact kernel too slow here for any long run to judge (stationarity: above)
                lam2 = float(np.sort(np.abs(np.linalg.eigvals(P.numpy())))[-2])
                relax = 1.0 / max(1.0 - lam2, 1e-300)
                if relax > n / 100:
                    pytest.skip(f"{problem}: the exact sweep matrix relaxes in {relax:.3g} sweeps, too slow for {n}")
        assert z[worst] <= self.z_long, (
            f"{problem}: cell {worst} at {mean[worst]:.4f} after {n} sweeps, exact {exact[worst]:.4f} "
            f"({z[worst]:.1f} standard errors of {se[worst]:.4f})"
        )

    def test_contract_region_samples_the_exact_conditional(self):
        if not self.supports_region:
            pytest.skip("this kernel takes no region")
        model = self.problem_region()
        kernel = self.make_kernel(model, region=self.region)
        torch.manual_seed(0)
        kernel.setup()
        start = kernel.state.copy()
        sampled = kernel.sampled_cells()
        assert np.isin(np.intersect1d(self.region, model.latent.numpy()), sampled).all()
        frozen = ~np.isin(np.arange(model.num_cells), sampled)
        params = kernel.current_params()
        for _ in range(50):
            params = kernel.sample(params)
            np.testing.assert_array_equal(kernel.state[frozen], start[frozen])
        S = enumerate_maps(model)
        keep = (S[:, torch.from_numpy(frozen)] == torch.from_numpy(start[frozen]).double()).all(1)
        lp = brute_force(model).log_probs.masked_fill(~keep, -math.inf)
        self._check_stationary(kernel, torch.softmax(lp, 0), "region")
