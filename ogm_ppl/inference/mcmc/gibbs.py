r"""Gibbs sampling of whole maps as Pyro ``MCMCKernel``\ s (Chapter 4; Algorithms 1 and 2).

* :class:`CellGibbs` — single-cell Gibbs (Section 4.1, Eq. 4.2):
  ``l(m_k | z, m_{-k}) = l(m_k | m_{-k}) + sum_n log p(z_n | m_k = 1, .) / p(z_n | m_k = 0, .)``.
* :class:`PatchGibbs` — blocks of ``L`` cells drawn from their ``W = 2^L`` configurations (Section 4.2,
  Eq. 4.4, Algorithm 1); with ``p_rand_patch > 0`` a random configuration is proposed instead, as in
  Algorithm 2, and accepted by Metropolis-Hastings so that the posterior stays invariant.
* :class:`MetropolisCell` — single-cell Metropolis-Hastings flips, with uniform or endpoint-weighted
  ("heat map", Dhiman et al. 2014) cell proposals, for comparing samplers on the same model.

Each kernel runs through ``pyro.infer.MCMC`` (site ``"m"``: the whole map as float 0/1) or through
:func:`~ogm_ppl.inference.mcmc.runner.run_gibbs` (streamed statistics, checkpoints). One ``sample`` call is one
*sweep*: as many cell / patch updates as there are latent cells / patches. The likelihood of a flip costs
only the rays through the cell, and rays blocked before it are skipped (Section 4.1.2), in compiled
kernels. Random numbers come from torch's global generator (the single-cell kernels draw one seed a sweep
from it, for a compiled SplitMix64 stream of the order and the uniforms), so ``pyro.set_rng_seed`` (or
``torch.manual_seed``) makes a run reproducible.

Scans: ``"systematic"`` (default: a fixed order, the fastest), ``"permutation"`` (a fresh random order
every sweep) or ``"random"`` (Algorithm 1 as printed: updates at uniformly random cells / patch
positions, with replacement). All leave the posterior invariant.

``region=`` (every kernel) restricts sampling to part of the map, the speed-up the thesis suggests after
Table 6.6 (Section 6.2.1: sample only mapped cells or cells near them, Fig. 6.16b; see
:func:`~ogm_ppl.metrics.near_mapped_mask`). The other cells keep their initial / current values, so the
chain samples the *conditional* ``p(m_R' | m_rest, z)``, not the full posterior, where ``R'``
(:meth:`~ogm_ppl.inference.mcmc.kernel.MapKernel.sampled_cells`) is the set of cells the kernel can change: the
latent region cells for
single-cell kernels, every latent cell of the visited patches for :class:`PatchGibbs`.

Priors with a compiled face (``prior.compiled()``, a bundle of :mod:`ogm_ppl.priors.compiled`: independent
cells; a stencil of unary + pairwise weights such as :class:`~ogm_ppl.priors.MRFPrior` /
:class:`~ogm_ppl.priors.StencilPrior`; tiles of a table such as :class:`~ogm_ppl.priors.PatchTablePrior` /
:class:`~ogm_ppl.priors.BorderPatchPrior`) use compiled sweeps specialised for the bundle's type, and patch
updates of table priors weigh only the configurations the table
allows given the border (so 5 x 5 patches are possible). Any other :class:`~ogm_ppl.priors.MapPrior` goes
through its ``log_prob_patch`` one update at a time (correct and overflow-free, but meant for small maps).

.. note:: ``pyro.infer.MCMC`` keeps every sample in memory (``num_samples x K``). For large maps pass a
   :class:`~ogm_ppl.inference.mcmc.runner.RunningStats` as ``hook_fn`` and few samples, or use ``run_gibbs``.
"""

from __future__ import annotations

import math

import numpy as np
import torch

from ogm_ppl.inference._kernels import cell_sweep as cs
from ogm_ppl.inference._kernels.choice import accept_random, choose
from ogm_ppl.inference._kernels.patch_lik import patch_log_lik
from ogm_ppl.inference._kernels.patch_state import (
    PatchGeometry,
    PatchRule,
    build_patch_at,
    patch_config,
    patch_state,
    set_patch,
)
from ogm_ppl.inference._kernels.patch_sweep import patch_log_weights, patch_sweep
from ogm_ppl.inference.mcmc.kernel import KernelStateError, MapKernel, initial_map
from ogm_ppl.inference.tiling import patch_cells, patch_shape, tiling_starts
from ogm_ppl.models.occupancy import OccupancyModel

__all__ = ["CellGibbs", "PatchGibbs", "MetropolisCell", "initial_map"]

_UPDATES = {"gibbs": cs.HEAT_BATH, "metropolised": cs.METROPOLISED}
_SCAN_CODES = {"systematic": cs.SYSTEMATIC, "permutation": cs.PERMUTATION, "random": cs.RANDOM}


class CellGibbs(MapKernel):
    """Single-cell Gibbs sampling of the map (Section 4.1; Algorithm 1 with ``L = 1``).

    Args:
        model: an :class:`~ogm_ppl.OccupancyModel`.
        scan: ``"systematic"`` (default; the fastest, cache-friendly), ``"permutation"`` (a fresh random
            order each sweep) or ``"random"`` (cells drawn with replacement).
        update: ``"gibbs"`` (the thesis's heat bath, ``m_k ~ p(m_k | m_-k, z)``, Eq. 4.2) or
            ``"metropolised"`` (Liu 1996: propose the flip, accept with ``min(1, p(flip) / p(stay))``;
            it moves at least as often, so it is no worse in Peskun's order; see ``benchmarks/bench_mixing.py``).
        init: starting map, see :func:`initial_map` (default: thresholded traditional OGM).
        region: ``None`` (every latent cell) or the cells to update (boolean mask of ``K`` cells or of the
            grid's shape, or cell indices): only the latent region cells change, the rest stay at their
            initial / current values, so the chain samples ``p(m_region | m_rest, z)`` (the speed-up the thesis
            suggests after Table 6.6: sample only cells near mapped cells).

    >>> import pyro
    >>> from pyro.infer import MCMC
    >>> from ogm_ppl import GaussianRange, OccupancyModel, raycast
    >>> from ogm_ppl.datasets import toy_1d
    >>> from ogm_ppl.priors import IndependentPrior
    >>> toy = toy_1d(num_cells=15, readings=[11.0, 7.0, 8.0, 8.0, 5.0, 9.0])
    >>> model = OccupancyModel(toy.grid, raycast(toy.grid, toy.scans), GaussianRange(3.0), IndependentPrior(0.5, 15))
    >>> mcmc = MCMC(CellGibbs(model), num_samples=50, warmup_steps=5, disable_progbar=True)
    >>> mcmc.run()
    >>> mcmc.get_samples()["m"].shape  # the 14 latent cells (cell 0 holds the robot)
    torch.Size([50, 14])
    >>> model.full_map(mcmc.get_samples()["m"]).shape
    torch.Size([50, 15])
    """

    def __init__(
        self,
        model: OccupancyModel,
        scan: str = "systematic",
        update: str = "gibbs",
        init="ogm",
        delta="haehnel",
        region=None,
    ) -> None:
        if update not in _UPDATES:
            raise ValueError(f"update must be one of {tuple(_UPDATES)}, got {update!r}")
        super().__init__(model, scan, init, delta, region)
        self.update = update
        self._rule = _UPDATES[update]

    def _set_up(self) -> None:
        super()._set_up()
        self._bits = cs.fixed_point_bits(self._ll, self._c_off)

    def _load_map(self, m: np.ndarray) -> None:
        super()._load_map(m)
        self._st = cs.cell_state_of(m, self._index, self._bits)
        self.chain.f = self._st.rays["f"]  # a view: the compiled sweeps keep it in step with the map

    def _sweep_order(self) -> np.ndarray | None:
        """The cells to visit this sweep, in order, if drawn here; ``None``: by ``scan``, in compiled code."""
        return None

    def _sweep(self) -> int:
        # One seed a sweep from torch's generator (so torch.manual_seed / pyro.set_rng_seed fix the chain);
        # the order and the uniforms come from the compiled SplitMix64 stream it seeds (cs.draws).
        seed = np.uint64(int(torch.randint(0, 2**63 - 1, (), dtype=torch.int64)))
        order = self._sweep_order()
        if order is None:
            order, u = cs.draws(self._visit, _SCAN_CODES[self.scan], seed)
        else:
            u = cs.draws(order, cs.SYSTEMATIC, seed)[1]
        self.chain.updates += len(order)
        if self._compiled is not None:
            return cs.sweep(self._st, order, self._compiled, u, self._rule)
        return self._generic_sweep(order, u)

    def run_marginals(self, num_sweeps: int, seed: int = 0) -> torch.Tensor:
        """Marginals from ``num_sweeps`` systematic sweeps run in one compiled call (numba's generator,
        seeded by ``seed``), continuing from the current state: for long runs on small maps, where one
        Python call per sweep would dominate. Priors with a compiled face only."""
        self._prepare()
        if self._compiled is None:
            raise ValueError("run_marginals needs a prior with a compiled face (prior.compiled())")
        if not self.chain.loaded:
            self.setup()
        acc = cs.marginals(self._st, self._visit, self._compiled, int(num_sweeps), int(seed), self._rule)
        self.chain.swept(0, int(num_sweeps))  # the changes are not counted here
        return torch.from_numpy(acc / max(int(num_sweeps), 1))

    def cell_log_odds(self, k: int) -> float:
        """``l(m_k | z, m_{-k})`` at the current state (Eq. 4.2)."""
        self._prepare()
        lik = cs.log_lik_ratio(self._st, int(k))
        if self._compiled is not None:
            return float(cs.prior_log_odds(self._compiled, int(k), self.state) + lik)
        cur = torch.from_numpy(self.state.astype(np.float64))
        lp = self.model.prior.log_prob_patch(cur, torch.tensor([int(k)]), torch.tensor([[0.0], [1.0]]))
        if not torch.isfinite(lp).any():
            return float("nan")
        if not torch.isfinite(lp).all():
            return math.inf if lp[1] > lp[0] else -math.inf
        return float(lp[1] - lp[0]) + lik

    def _generic_sweep(self, order, u) -> int:
        changes = 0
        m = self.state
        for k, uk in zip(order.tolist(), u.tolist()):
            v = cs.new_value(self.cell_log_odds(k), uk, int(m[k]), self._rule)
            if v != m[k]:
                cs.set_cell(self._st, k, v)
                changes += 1
        return changes


class MetropolisCell(CellGibbs):
    """Single-cell Metropolis-Hastings: propose flipping a cell, accept with ``min(1, ratio)``.

    ``proposal="uniform"`` visits latent cells in the order ``scan`` (``"random"``, the default: drawn
    with replacement; ``"permutation"``; ``"systematic"``, which is ``CellGibbs(update="metropolised")``);
    ``"endpoint"`` draws cells holding a laser end point ``endpoint_weight`` times as often (the "heat
    map" proposal of Dhiman et al., ICRA 2014; random scan only). Cell choices do not depend on the
    state, so the flip proposal is symmetric and any prior works. ``region``: as in :class:`CellGibbs`
    (proposals only at latent region cells, ``len(latent ∩ region)`` per sweep).
    """

    def __init__(
        self,
        model,
        proposal: str = "uniform",
        endpoint_weight: float = 4.0,
        scan: str = "random",
        init="ogm",
        delta="haehnel",
        region=None,
    ) -> None:
        super().__init__(model, scan, "metropolised", init, delta, region)
        if proposal not in ("uniform", "endpoint"):
            raise ValueError(f"proposal must be 'uniform' or 'endpoint', got {proposal!r}")
        if proposal == "endpoint" and scan != "random":
            raise ValueError("the endpoint proposal draws cells at random: use scan='random'")
        if not endpoint_weight > 0:
            raise ValueError(f"endpoint_weight must be positive, got {endpoint_weight}")
        self.proposal = proposal
        self.endpoint_weight = float(endpoint_weight)
        self._weights = None

    def proposal_probs(self) -> torch.Tensor:
        """Probability of proposing each latent cell (in ``model.latent`` order) in a random scan."""
        if self._weights is None:
            w = torch.ones(len(self.model.latent), dtype=torch.float64)
            if self.proposal == "endpoint":
                ends = torch.zeros(self.model.num_cells, dtype=torch.bool)
                ends[torch.from_numpy(self.model.rays.endpoint_cells())] = True
                w[ends[self.model.latent]] = self.endpoint_weight
            if self.region is not None:
                w[~torch.from_numpy(np.isin(self.model.latent.numpy(), self.region))] = 0.0
            self._weights = w / w.sum()
        return self._weights

    def _sweep_order(self) -> np.ndarray | None:
        n = len(self._visit)
        if self.proposal != "endpoint" or n == 0:  # uniform over the visited cells: drawn by scan
            return super()._sweep_order()
        picks = torch.multinomial(self.proposal_probs(), n, replacement=True).numpy()
        return np.ascontiguousarray(self._latent[picks])


class PatchGibbs(MapKernel):
    """Patch Gibbs sampling (Section 4.2, Algorithm 1; Algorithm 2 with ``p_rand_patch``).

    Args:
        model: an :class:`~ogm_ppl.OccupancyModel`.
        patch: the patch shape, see :func:`patch_shape` (``3`` for a 1D run of 3, ``(3, 3)``, ``"plus"``).
        scan: ``"systematic"`` / ``"permutation"`` visit a fixed set of patch positions (a tiling for runs
            and rectangles in which a patch starts at column ``offset`` (or at ``(row, col)``); every cell's
            neighbourhood for other shapes);
            ``"random"`` (Algorithm 1) places the patch at uniformly random cells, ``ceil(K / L)`` times
            per sweep.
        p_rand_patch: Algorithm 2's probability of proposing a random configuration instead (0.001 in the
            thesis), accepted by Metropolis-Hastings unless ``random_patch="thesis"``.
        update: ``"gibbs"`` (the thesis's heat bath: draw the patch from its conditional),
            ``"metropolised"`` (propose one of the *other* configurations in proportion to its
            conditional, accept by Metropolis-Hastings with ``min(1, (1 - p_cur) / (1 - p_new))``) or
            ``"thesis"``, the border update of Section 5.2.3 for table priors whose tiles are the patches:
            each tile drawn from ``p(a_k | border_k) p(z | a_k, rest)`` over the table's support, the
            factors of the neighbouring tiles (whose borders the tile forms) ignored. That is not a Gibbs
            sampler of the tiled joint, nor of any joint in general: its stationary distribution differs
            from the posterior (:func:`ogm_ppl.studies.thesis_border_update.thesis_border_update` measures by how much).
        p_escape: for backed-off tables (strictly positive, e.g. ``border_bo``), the probability per patch
            update of the escape move (an independence Metropolis-Hastings proposal from the back-off
            table after the heat bath on the counted configurations; see
            :func:`~ogm_ppl.inference._kernels.candidate_sweep._restricted_update`); it makes the chain irreducible.
            Unused by other priors.
        region: ``None`` (the whole map) or cells (boolean mask of ``K`` cells or of the grid's shape, or
            cell indices): the systematic / permutation scans visit only the fixed patches that hold a
            latent region cell; the random scan places patches at latent region cells,
            ``ceil(|latent ∩ region| / L)`` per sweep. Cells outside those patches keep their initial /
            current values, so the chain samples exactly ``p(m_R' | m_rest, z)`` with ``R'`` the cells the
            visited patches cover (:meth:`sampled_cells`; it may reach a little past the region). This is the
            speed-up the thesis suggests after Table 6.6 (Section 6.2.1): sample only cells near mapped cells.
    """

    def __init__(
        self,
        model,
        patch=3,
        scan: str = "systematic",
        offset=0,
        p_rand_patch: float = 0.0,
        random_patch: str = "mh",
        update: str = "gibbs",
        init="ogm",
        delta="haehnel",
        region=None,
        p_escape: float = 0.2,
    ) -> None:
        if update not in (*_UPDATES, "thesis"):
            raise ValueError(f"update must be one of {(*_UPDATES, 'thesis')}, got {update!r}")
        if not 0.0 < p_escape <= 1.0:
            raise ValueError(f"p_escape must lie in (0, 1], got {p_escape}")
        super().__init__(model, scan, init, delta, region)
        self.update = update
        self.p_escape = float(p_escape)
        self._metropolised = update == "metropolised"
        compiled = model.prior.compiled()
        # patches of up to 62 cells where the prior's kind weighs only its sparse support (tiles as patches)
        sparse = compiled is not None and scan != "random" and compiled.sparse_patches()
        self.dr, self.dc = patch_shape(patch, model.grid.ndim, max_cells=62 if sparse else 20)
        if not 0.0 <= p_rand_patch < 1.0:
            raise ValueError(f"p_rand_patch must lie in [0, 1), got {p_rand_patch}")
        if random_patch not in ("mh", "thesis"):
            raise ValueError(f"random_patch must be 'mh' or 'thesis', got {random_patch!r}")
        self.p_rand_patch = float(p_rand_patch)
        self.thesis_random = random_patch == "thesis"
        self.offset = offset
        self._stamp = 0
        self._anchors = self._fixed_anchors()
        if self.scan != "random" and len(self._anchors) == 0:
            raise ValueError("no patch holds a latent cell")
        self._hw = self._rectangle()
        if update == "thesis" and not (
            compiled is not None and scan != "random" and compiled.tiles_patches(self._hw, self._anchors)
        ):
            raise ValueError(
                "update='thesis' draws each tile of a table prior from its own table: it needs a table "
                "prior whose tiles are the patches (same shape, aligned: offset = prior.origin) and a "
                "systematic or permutation scan"
            )
        if self.L > 20 and not (compiled is not None and compiled.tiles_patches(self._hw, self._anchors)):
            raise ValueError(
                f"patches of {self.L} cells (2^{self.L} configurations) need a table prior whose "
                "tiles are the patches (same shape, aligned: offset = prior.origin)"
            )

    def _rectangle(self) -> tuple[int, int]:
        if self.dr.min() == 0 and self.dc.min() == 0 and len(self.dr) == (self.dr.max() + 1) * (self.dc.max() + 1):
            h, w = int(self.dr.max()) + 1, int(self.dc.max()) + 1
            if np.array_equal(self.dr * w + self.dc, np.arange(h * w)):  # row-major, as tiles are
                return h, w
        return 0, 0

    @property
    def L(self) -> int:
        return len(self.dr)

    def _fixed_anchors(self) -> np.ndarray:
        """``n x 2`` (row, col) patch positions for the systematic / permutation scans."""
        g = self.model.grid
        rows, cols = g.rows, g.cols
        is_rect = (
            self.dr.min() == 0 and self.dc.min() == 0 and len(self.dr) == (self.dr.max() + 1) * (self.dc.max() + 1)
        )
        if is_rect:
            h, w = int(self.dr.max()) + 1, int(self.dc.max()) + 1
            orow, ocol = (
                (0, int(self.offset)) if isinstance(self.offset, (int, np.integer)) else (int(o) for o in self.offset)
            )
            r0 = tiling_starts(orow, h, rows)
            c0 = tiling_starts(ocol, w, cols)
        else:
            r0, c0 = np.arange(rows), np.arange(cols)
        R, C = np.meshgrid(r0, c0, indexing="ij")
        anchors = np.stack([R.ravel(), C.ravel()], 1).astype(np.int64)
        pc = patch_cells(self.model, anchors, self.dr, self.dc)
        live = (pc >= 0).any(1)
        if self.region is not None:  # only the patches that hold a (latent) region cell
            in_region = np.zeros(self.model.num_cells + 1, np.bool_)  # index -1 (no cell) reads the last: False
            in_region[self.region] = True
            live &= in_region[pc].any(1)
        return np.ascontiguousarray(anchors[live])

    def sampled_cells(self) -> np.ndarray:
        """The cells ``R'`` the visited patches cover (sorted; every latent cell without ``region``)."""
        if self.region is None:
            return super().sampled_cells()
        if self.scan == "random":
            g = self.model.grid
            anchors = np.stack(np.divmod(self._visit, g.cols), 1)
        else:
            anchors = self._anchors
        pc = patch_cells(self.model, anchors, self.dr, self.dc)
        return np.unique(pc[pc >= 0])

    def patches(self) -> list[np.ndarray]:
        """The fixed patch positions as arrays of cells (``-1`` where cut off or pinned)."""
        return list(patch_cells(self.model, self._anchors, self.dr, self.dc))

    def _sweep(self) -> int:
        g = self.model.grid
        if self.scan == "random":
            pool = self._visit  # latent cells (of the region)
            n = math.ceil(len(pool) / self.L)
            cells = pool[torch.randint(0, len(pool), (n,)).numpy()] if n else pool
            anchors = np.ascontiguousarray(np.stack(np.divmod(cells, g.cols), 1).astype(np.int64))
        else:
            anchors = self._order(self._anchors)
        n = len(anchors)
        rows = 5 if self._escapes() else 3  # choice, random patch, accept (, escape: proposal, accept)
        u = np.stack([self._uniforms(n) for _ in range(rows)])
        self.chain.updates += n
        if self._compiled is None:
            return self._python_sweep(anchors, u[0], u[1], u[2])
        changed, skipped = patch_sweep(self._ps, self._geometry(), anchors, self._compiled, u, self._patch_rule())
        if skipped:
            raise RuntimeError(f"{skipped} patch updates had more configurations than fit")
        return changed

    def _load_map(self, m: np.ndarray) -> None:
        super()._load_map(m)
        self._ps = patch_state(m, self.first_hit_state, self._index)  # views: the sweeps keep them in step

    def _geometry(self) -> PatchGeometry:
        g = self.model.grid
        h, w = self._hw
        return PatchGeometry(self.dr, self.dc, h, w, g.rows, g.cols, self._pinned)

    def _extra_state(self) -> dict[str, np.ndarray]:
        return {"update": np.asarray(self.update)}

    def _load_extra_state(self, state) -> None:
        """A checkpoint taken with another update rule (say the thesis's inexact border update) is refused;
        checkpoints that do not record the rule load as before."""
        if "update" in state:
            u = np.asarray(state["update"])
            if u.shape != () or u.dtype.kind != "U" or str(u) != self.update:
                raise KernelStateError(f"PatchGibbs state was taken with update={u!s}, this kernel has {self.update!r}")

    def _escapes(self) -> bool:
        """Whether the prior's patch updates add the escape move (a backed-off table)."""
        self._prepare()
        return self._compiled is not None and bool(getattr(self._compiled, "needs_escape", lambda: False)())

    def _patch_rule(self) -> PatchRule:
        capacity = self._compiled.patch_capacity(self.L) if self._compiled is not None else 2
        return PatchRule(
            self.p_rand_patch,
            self.thesis_random,
            self._metropolised,
            capacity,
            self.p_escape,
            self.update == "thesis",
        )

    def patch_log_weights(self, patch: np.ndarray) -> np.ndarray:
        """Unnormalised log conditional of each configuration of ``patch`` (grid cells, ``-1`` = none)
        at the current state: bit ``j`` of configuration ``w`` is the ``j``-th live cell."""
        self._prepare()
        patch = np.ascontiguousarray(patch, dtype=np.int64)
        logw = np.empty(1 << int((patch >= 0).sum()), np.float64)
        if self._compiled is not None:
            return logw[: patch_log_weights(self._ps, patch, self._compiled, logw)].copy()
        W = patch_log_lik(self._ps, patch, logw)
        live = patch[patch >= 0]
        configs = ((torch.arange(W)[:, None] >> torch.arange(len(live))) & 1).to(torch.float64)
        cur = torch.from_numpy(self.state.astype(np.float64))
        prior = self.model.prior.log_prob_patch(cur, torch.from_numpy(live), configs).numpy()
        return logw[:W] + prior

    def _python_sweep(self, anchors, u_choice, u_rand, u_accept) -> int:
        """The generic path: each patch weighed through the prior's ``log_prob_patch``, then the same
        choice step as the compiled sweeps."""
        geo = self._geometry()
        p = np.empty(self.L, np.int64)
        m = self.state
        changed = 0
        for i, a in enumerate(anchors):
            if build_patch_at(geo, int(a[0]), int(a[1]), p) == 0:
                continue
            logw = np.ascontiguousarray(self.patch_log_weights(p))
            W = len(logw)
            cur = patch_config(p, m)
            if self.p_rand_patch > 0 and u_rand[i] < self.p_rand_patch:
                prop = min(int(u_choice[i] * W), W - 1)
                new = prop if (self.thesis_random or accept_random(logw[cur], logw[prop], u_accept[i])) else cur
            else:
                new = choose(logw, W, cur, u_choice[i], u_accept[i], self._metropolised, np.empty(W))
                if new < 0:
                    continue
            if new != cur:
                set_patch(self._ps, p, new)
                changed += 1
        return changed
