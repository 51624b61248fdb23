r"""Data-driven MCMC: Gibbs sweeps mixed with independence Metropolis-Hastings moves proposed by an
amortised guide (Chapter 4 with the guide of :mod:`ogm_ppl.inference.variational.amortised`).

A guide ``q(m | z) = prod_k q_k^{m_k} (1 - q_k)^{1 - m_k}`` (mean field, a function of the readings only)
proposes a whole block ``B`` of cells at once (a window of a tiling with a random offset, or every latent
cell), independently of the block's current values; the rest of the map is kept. The move
``m -> m' = (m'_B, m_{-B})`` is accepted with

.. math::
    \alpha(m, m') = \min\Bigl(1,\ \frac{p(m') \, p(z \mid m') \, q_B(m_B)}
                                     {p(m) \, p(z \mid m) \, q_B(m'_B)}\Bigr),

an independence Metropolis-Hastings step within Gibbs (Metropolis-within-Gibbs on block ``B``;
Tierney 1994), so the exact posterior ``p(m | z)`` is stationary for each block move, hence for a pass
over a tiling, for the mixture over random offsets, and for its mixture with any Gibbs sweep that leaves
it stationary (Section 4.1, 4.2). Only what changes is computed: the prior through
``prior.log_prob_patch`` (exact differences between configurations of the block; the whole ``log_prob``
for blocks of more than 48 cells) and the likelihood through the rays that cross the block
(``sum_{n: B cap ray_n != {}} log p(z_n | f_n(m))``, Eq. 2.6).

:class:`GuidedGibbs` is a :class:`~ogm_ppl.inference.mcmc.kernel.MapKernel` like
:class:`~ogm_ppl.inference.mcmc.gibbs.CellGibbs`
(one ``sample`` call is one sweep: with probability ``p_guide`` a pass of guide moves over the blocks,
otherwise one sweep of the wrapped base kernel) and runs under ``pyro.infer.MCMC`` or
:func:`~ogm_ppl.inference.mcmc.runner.run_gibbs`. By default it also starts from the guide's mode
(``init="guide"``), the second use of the guide.
"""

from __future__ import annotations

import math
from collections import OrderedDict

import numpy as np
import torch

from ogm_ppl.inference.mcmc.kernel import KernelStateError, MapKernel
from ogm_ppl.inference.tiling import patch_cells, tiling_starts

__all__ = ["GuidedGibbs"]

_INITS = ("guide", "guide_sample", "base")
_MAX_PATCH_PRIOR = 48


class GuidedGibbs(MapKernel):
    """Gibbs sweeps of a base kernel mixed with block proposals from an amortised guide (module docstring).

    Args:
        base: the Gibbs kernel to wrap (a :class:`~ogm_ppl.inference.mcmc.kernel.MapKernel`:
            :class:`~ogm_ppl.inference.mcmc.gibbs.CellGibbs`, ``PatchGibbs``, ``MetropolisCell``), kept
            in step with this kernel's state through its public protocol; its checkpoint entries are
            this kernel's ``base.*`` entries.
        guide: an :class:`~ogm_ppl.inference.variational.amortised_guide.AmortisedGuide` (anything with
            ``cell_logits(model)``: ``K`` logits of ``q(m_k = 1 | z)``).
        block: the proposal block: ``(h, w)`` windows of a tiling (an int ``w``: ``(1, w)``), or ``"all"``
            (every latent cell at once: an independence sampler, for small maps).
        p_guide: probability that a sweep is a pass of guide moves instead of a base sweep (``1``: guide
            moves only).
        init: ``"guide"`` (the guide's mode, :func:`guide_initial_map`), ``"guide_sample"`` (a draw from
            the guide) or ``"base"`` (the base kernel's own initialisation).
        random_offset: draw the tiling's offset uniformly at every pass (blocks then straddle every
            boundary); ``False`` keeps offset ``(0, 0)``.
        proposal: ``"bernoulli"`` (the guide's independent cells) or ``"tiles"``, for a tile prior
            (:class:`~ogm_ppl.priors.PatchTablePrior`) and blocks made of whole tiles: each tile of the block
            drawn from its table tilted by the guide,
            ``q_t(c) ∝ p_t(c) prod_{k in t} exp(c_k [logit q_k - logit lambda_k])`` (``lambda_k``: the
            table's occupancy at the tile position), which keeps the guide's evidence and the table's
            support (independent cells rarely hit one of a sparse table's configurations). Offsets are
            then multiples of the tile size; ``init="guide"`` starts from every tile's most likely tilted
            configuration.
    """

    def __init__(
        self,
        base,
        guide,
        block=(6, 6),
        p_guide: float = 0.5,
        init: str = "guide",
        random_offset: bool = True,
        proposal: str = "bernoulli",
    ) -> None:
        if not 0.0 <= float(p_guide) <= 1.0:
            raise ValueError(f"p_guide must lie in [0, 1], got {p_guide}")
        if init not in _INITS:
            raise ValueError(f"init must be one of {_INITS}, got {init!r}")
        if not isinstance(base, MapKernel):
            raise TypeError(f"base must be a MapKernel (CellGibbs, PatchGibbs, ...), got {type(base).__name__}")
        super().__init__(base.model)
        self.base = base
        self.guide = guide
        self.p_guide = float(p_guide)
        self.init = init
        self.random_offset = bool(random_offset)
        if proposal not in ("bernoulli", "tiles"):
            raise ValueError(f"proposal must be 'bernoulli' or 'tiles', got {proposal!r}")
        self.proposal = proposal
        self.block = self._check_block(block)
        self.guide_sweeps = 0
        self._proposed = 0
        self._same = 0
        self._accepted = 0
        self._base_stale = True  # the base kernel's state differs from ours: load ours before its sweep
        self._blocks: dict = {}
        with torch.no_grad():
            lg = torch.as_tensor(guide.cell_logits(self.model), dtype=torch.float64).detach().clone()
        if lg.shape != (self.model.num_cells,) or torch.isnan(lg).any():
            raise ValueError(f"the guide's cell_logits must be {self.model.num_cells} numbers (no NaN)")
        self.guide_logits = lg  # public: a run's fingerprint sees the proposal
        self._q = torch.sigmoid(lg)
        self._log_q1 = torch.nn.functional.logsigmoid(lg)
        self._log_q0 = torch.nn.functional.logsigmoid(-lg)
        self._lq1, self._lq0 = self._log_q1.numpy(), self._log_q0.numpy()
        r = self.model.rays
        dense = np.full((r.num_rays, int(r.lengths.max())), self.model.num_cells, dtype=np.int64)
        dense[r.ray_of_entry, r.kappa] = r.cells  # padded with K: a cell that is always free
        self._dense, self._lengths = dense, r.lengths.astype(np.int64)
        self._loglik = np.ascontiguousarray(self.model.loglik_table.numpy())
        self._known_free = self.model.known_free.numpy()
        self._K = int(self.model.num_cells)
        lo = self.model.prior.cell_log_odds()
        self._cell_prior_lo = None if lo is None else torch.as_tensor(lo, dtype=torch.float64).numpy()
        self._tiles: dict = {}  # block cells (bytes) -> tile proposals, for proposal="tiles"
        if proposal == "tiles":
            self._check_tiles()

    # ------------------------------------------------------------------ blocks
    def _check_block(self, block):
        g = self.model.grid
        if isinstance(block, str):
            if block != "all":
                raise ValueError(f"block must be (h, w), an int or 'all', got {block!r}")
            return "all"
        hw = (1, int(block)) if np.isscalar(block) else tuple(int(v) for v in block)
        if len(hw) != 2 or hw[0] < 1 or hw[1] < 1:
            raise ValueError(f"block must be (h, w) of positive sizes, got {block!r}")
        if g.ndim == 1 and hw[0] != 1:
            raise ValueError("a 1D grid takes blocks (1, w)")
        return hw

    def offsets(self) -> list[tuple[int, int]]:
        """The tiling offsets a pass draws from (uniformly), or ``[(0, 0)]``."""
        if self.proposal == "tiles":
            (th, tw), (orow, ocol) = self.model.prior.patch, self.model.prior.origin
            h, w = self.block
            rows = [(orow + i * th) % h for i in range(h // th)]
            cols = [(ocol + j * tw) % w for j in range(w // tw)]
            return [(a, b) for a in rows for b in cols] if self.random_offset else [(rows[0], cols[0])]
        if self.block == "all" or not self.random_offset:
            return [(0, 0)]
        h, w = self.block
        return [(a, b) for a in range(h) for b in range(w)]

    def blocks(self, offset: tuple[int, int] = (0, 0)) -> list[tuple[np.ndarray, np.ndarray]]:
        """The blocks of a pass at ``offset``: ``(cells, rays)`` pairs, the latent cells of each window (in
        tiling order) and the rays crossing them."""
        key = tuple(offset)
        if key in self._blocks:
            return self._blocks[key]
        model = self.model
        if self.block == "all":
            groups = [model.latent.numpy()]
        else:
            g = model.grid
            rows, cols = (g.rows, g.cols) if g.ndim == 2 else (1, g.num_cells)
            h, w = self.block
            r0, c0 = tiling_starts(key[0], h, rows), tiling_starts(key[1], w, cols)
            R, C = np.meshgrid(r0, c0, indexing="ij")
            anchors = np.stack([R.ravel(), C.ravel()], 1)
            dr, dc = np.divmod(np.arange(h * w), w)
            if g.ndim == 1:
                k = anchors[:, 1:] + dc[None, :]
                inside = (k >= 0) & (k < cols)
                ok = inside & ~model.known_free.numpy()[np.where(inside, k, 0)]
                cells = np.where(ok, k, -1)
            else:
                cells = patch_cells(model, anchors, dr, dc)
            i_live = [i for i, row in enumerate(cells) if (row >= 0).any()]
            groups = [cells[i][cells[i] >= 0] for i in i_live]
        out = []
        for i, cells in enumerate(groups):
            rays = self._rays_of(cells)
            cells = np.sort(cells).astype(np.int64)
            out.append((cells, rays.astype(np.int64)))
            if self.proposal == "tiles":
                self._tiles[cells.tobytes()] = self._tile_proposals(anchors[i_live[i]], cells)
        self._blocks[key] = out
        return out

    # ------------------------------------------------------------------ the MH ratio
    def _check_tiles(self) -> None:
        prior = self.model.prior
        if not all(hasattr(prior, k) for k in ("codes", "probs", "patch", "origin")) or self.model.grid.ndim != 2:
            raise ValueError("proposal='tiles' needs a 2D tile prior (PatchTablePrior: codes, probs, patch, origin)")
        th, tw = prior.patch
        if th * tw > 16:
            raise ValueError(
                f"proposal='tiles' tabulates every configuration of a tile: up to 16 cells, not {th} x {tw}"
            )
        if self.block == "all" or self.block[0] % th or self.block[1] % tw:
            raise ValueError(f"proposal='tiles' needs blocks of whole {th} x {tw} tiles, got {self.block!r}")

    def _tile_proposals(self, anchor, cells: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The tilted tables of the ``T`` tiles of the block at ``anchor``, packed: ``pos`` (``T x n``, the
        positions in ``cells`` of each tile's latent cells in row-major order, ``len(cells)`` padding),
        ``logq`` (``T x 2^n``, log proposal probability of each configuration code over those cells,
        bit ``j`` = ``j``-th, ``-inf`` off the table) and ``cdf`` (its cumulative sums)."""
        prior, g = self.model.prior, self.model.grid
        th, tw = prior.patch
        h, w = self.block
        pos = {int(c): i for i, c in enumerate(cells)}
        codes = np.asarray(prior.codes, dtype=np.int64)
        probs = np.asarray(prior.probs, dtype=np.float64)
        n = th * tw
        P, Q = [], []
        for r0 in range(int(anchor[0]), int(anchor[0]) + h, th):
            for c0 in range(int(anchor[1]), int(anchor[1]) + w, tw):
                bits, where = [], []
                in_mask = pin_mask = 0
                for i in range(n):
                    r, c = r0 + i // tw, c0 + i % tw
                    if 0 <= r < g.rows and 0 <= c < g.cols:
                        in_mask |= 1 << i
                        k = r * g.cols + c
                        if self._known_free[k]:
                            pin_mask |= 1 << i
                        else:
                            bits.append(i)
                            where.append(pos[k])
                if not bits:
                    continue
                keys, inv = np.unique(codes & in_mask, return_inverse=True)  # off-grid cells summed out
                p = np.bincount(inv.ravel(), weights=probs)
                keep = ((keys & pin_mask) == 0) & (p > 0)  # given the pinned cells are free
                keys, p = keys[keep], p[keep] / p[keep].sum()
                b = np.asarray(bits, dtype=np.int64)
                on = (keys[:, None] >> b[None, :]) & 1  # configurations x latent bits
                lam = np.clip(p @ on, 1e-12, 1 - 1e-12)
                k_cells = cells[np.asarray(where)]
                tilt = self._lq1[k_cells] - self._lq0[k_cells] - (np.log(lam) - np.log1p(-lam))
                tilt = np.where((lam <= 1e-12) | (lam >= 1 - 1e-12), 0.0, tilt)
                logw = np.log(p) + on @ tilt
                table = np.full(1 << n, -np.inf)
                table[(on << np.arange(len(b))[None, :]).sum(1)] = logw - np.logaddexp.reduce(logw)
                P.append(np.r_[where, np.full(n - len(where), len(cells))])
                Q.append(table)
        logq = np.array(Q)
        return np.array(P, dtype=np.int64), logq, np.cumsum(np.exp(logq), 1)

    def _tiles_of(self, cells: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        t = self._tiles.get(np.asarray(cells, dtype=np.int64).tobytes())
        if t is None:
            raise ValueError("proposal='tiles' scores only the blocks of its own tilings (see blocks())")
        return t

    def proposal_log_prob(self, cells, values) -> torch.Tensor:
        """``log q_B(values)`` of configurations ``... x |B|`` of the block's ``cells``."""
        cells = np.asarray(cells.numpy() if isinstance(cells, torch.Tensor) else cells, dtype=np.int64)
        v = np.asarray(values.numpy() if isinstance(values, torch.Tensor) else values, dtype=np.float64)
        return torch.from_numpy(self._proposal_lq(cells, v))

    def _proposal_lq(self, cells: np.ndarray, v: np.ndarray) -> np.ndarray:
        v2 = np.asarray(v, dtype=np.float64).reshape(-1, len(cells))
        if self.proposal == "bernoulli":
            out = v2 @ self._lq1[cells] + (1 - v2) @ self._lq0[cells]
        else:
            pos, logq, _ = self._tiles_of(cells)
            vv = np.concatenate([v2, np.zeros((len(v2), 1))], 1).astype(np.int64)  # padding column: 0
            code = (vv[:, pos] << np.arange(pos.shape[1])).sum(2)  # W x T
            out = logq[np.arange(len(pos))[None, :], code].sum(1)
        return out.reshape(np.shape(v)[:-1])

    def _propose(self, cells: np.ndarray) -> np.ndarray:
        """A draw of the block's cells from the proposal."""
        if self.proposal == "bernoulli":
            return (torch.rand(len(cells), dtype=torch.float64).numpy() < self._q.numpy()[cells]).astype(np.float64)
        pos, _, cdf = self._tiles_of(cells)
        u = torch.rand(len(pos), dtype=torch.float64).numpy() * cdf[:, -1]
        code = np.minimum((cdf <= u[:, None]).sum(1), cdf.shape[1] - 1)  # inverse CDF
        new = np.zeros(len(cells) + 1)
        new[pos] = (code[:, None] >> np.arange(pos.shape[1])) & 1
        return new[:-1]

    def _rays_of(self, cells: np.ndarray) -> np.ndarray:
        idx = self.model.rays.by_cell
        parts = [idx.ray[idx.offsets[k] : idx.offsets[k + 1]] for k in cells.tolist()]
        return np.unique(np.concatenate(parts + [np.zeros(0, np.int64)])).astype(np.int64)

    def _lik(self, maps: np.ndarray, rays: np.ndarray) -> np.ndarray:
        """``sum_{n in rays} log p(z_n | f_n(m))`` of maps ``W x (K + 1)`` (a trailing 0 column) -> ``W``."""
        occ = maps[:, self._dense[rays]] != 0  # W x |rays| x Lmax
        first = np.where(occ.any(2), occ.argmax(2), self._lengths[rays][None, :])
        return self._loglik[rays[None, :], first].sum(1)

    def log_ratio(self, m, cells, new, rays=None) -> float:
        r"""``log [p(m') p(z | m') q_B(m_B)] - log [p(m) p(z | m) q_B(m'_B)]`` for ``m' = m`` with
        ``m'_B = new`` (``m``: a full ``K`` map; ``rays``: those crossing ``cells``, found if ``None``).

        ``+inf`` if ``m`` has zero posterior mass and ``m'`` has some (the move is always taken), ``-inf``
        if ``m'`` has none (or ``new`` occupies a pinned cell)."""
        new = np.asarray(new.numpy() if isinstance(new, torch.Tensor) else new, dtype=np.float64)
        return float(self.log_ratios(m, cells, new[None, :], rays)[0])

    def log_ratios(self, m, cells, news, rays=None) -> np.ndarray:
        """:meth:`log_ratio` of ``W`` proposals at once (``news``: ``W x |B|``) -> ``W`` float64; the
        sampler calls it with ``W = 1``."""
        model = self.model
        K = self._K
        m = np.asarray(m.detach().cpu().numpy() if isinstance(m, torch.Tensor) else m, dtype=np.float64)
        cells = np.asarray(cells.numpy() if isinstance(cells, torch.Tensor) else cells, dtype=np.int64)
        news = np.asarray(news.numpy() if isinstance(news, torch.Tensor) else news, dtype=np.float64)
        if m.shape != (K,) or news.ndim != 2 or news.shape[1] != len(cells):
            raise ValueError(f"log_ratios takes a {K}-cell map and W x {len(cells)} block values")
        W = news.shape[0]
        old = m[cells]
        maps = np.zeros((W + 1, K + 1))
        maps[:, :K] = m
        maps[1:, cells] = news
        if self._cell_prior_lo is not None:  # independent cells: the prior ratio is local and exact
            lp = np.concatenate([[0.0], ((news - old) * self._cell_prior_lo[cells]).sum(1)])
        elif len(cells) <= _MAX_PATCH_PRIOR:  # exact differences between configurations of the block
            configs = torch.from_numpy(np.concatenate([old[None, :], news]))
            lp = torch.as_tensor(
                model.prior.log_prob_patch(torch.from_numpy(m), torch.from_numpy(cells), configs), dtype=torch.float64
            ).numpy()
        else:
            lp = torch.as_tensor(model.prior.log_prob(torch.from_numpy(maps[:, :K])), dtype=torch.float64).numpy()
        rays = (
            self._rays_of(cells)
            if rays is None
            else np.asarray(rays.numpy() if isinstance(rays, torch.Tensor) else rays, np.int64)
        )
        lj = lp + self._lik(maps, rays)
        if np.isnan(lj).any():
            raise FloatingPointError("the log joint of a block move is NaN")
        lq = self._proposal_lq(cells, np.concatenate([old[None, :], news]))
        with np.errstate(invalid="ignore"):
            out = lj[1:] - lj[0] + lq[0] - lq[1:]
        # q(old) = 0 (the move could not be undone): never taken; a state of zero mass: always left
        out = np.where((lj[1:] == -np.inf) | (lq[0] == -np.inf), -np.inf, np.where(lj[0] == -np.inf, np.inf, out))
        pinned = (news[:, self._known_free[cells]] != 0).any(1)
        return np.where(pinned, -np.inf, out)

    # ------------------------------------------------------------------ the MapKernel hooks
    def _set_up(self) -> None:
        """Nothing to set up: the base kernel sets up its own sweeps, and the guide's moves were set up when built."""

    def _initial_map(self) -> torch.Tensor:
        if self.init == "base":
            return self.model.full_map(self.base.initial_params[self.site]).to(torch.float64)
        if self.init == "guide" and self.proposal == "tiles":
            m = torch.zeros(self.model.num_cells, dtype=torch.float64)
            for cells, _ in self.blocks(self.offsets()[0]):  # blocks of one offset cover every latent cell
                pos, logq, _ = self._tiles_of(cells)
                v = np.zeros(len(cells) + 1)
                v[pos] = (np.argmax(logq, 1)[:, None] >> np.arange(pos.shape[1])) & 1
                m[torch.from_numpy(cells)] = torch.from_numpy(v[:-1])
        elif self.init == "guide":
            m = (self._q > 0.5).to(torch.float64)
        else:
            m = (torch.rand(self.model.num_cells, dtype=torch.float64) < self._q).to(torch.float64)
        m[self.model.known_free] = 0.0
        return m

    def _load_map(self, m: np.ndarray) -> None:
        self.chain.bind(m)  # the base kernel loads it when it next sweeps (and keeps its own first hits)
        self._base_stale = True

    def sampled_cells(self) -> np.ndarray:
        """Every latent cell (guide moves reach them all)."""
        return self.model.latent.numpy().astype(np.int64)

    def settings(self) -> dict:
        out = super().settings()
        out.pop("guide_sweeps", None)
        out["base"] = (type(self.base).__qualname__, self.base.settings())
        return out

    def _sweep(self) -> int:
        if self.p_guide >= 1.0 or (self.p_guide > 0.0 and float(torch.rand(())) < self.p_guide):
            before = self._proposed
            moved = self.mh_pass()
            self.chain.updates += self._proposed - before
            self._base_stale |= moved > 0
            self.guide_sweeps += 1
            return moved
        base = self.base
        if self._base_stale:
            base._adopt_map(self.state)
            self._base_stale = False
        changes, updates = base.changes, base.updates
        base.sample(base.current_params())
        self.state[:] = base.state
        self.chain.updates += base.updates - updates
        return base.changes - changes

    def mh_pass(self, offset: tuple[int, int] | None = None) -> int:
        """One pass of guide moves over the blocks of a tiling (offset drawn uniformly unless given), on
        the current state; returns the number of blocks that changed."""
        if not self.chain.loaded:
            self.setup()
        offs = self.offsets()
        if offset is None:
            offset = offs[int(torch.randint(len(offs), ()))] if len(offs) > 1 else offs[0]
        moved = 0
        mn = self.state  # moves write into the state
        for cells, rays in self.blocks(offset):
            new = self._propose(cells)
            self._proposed += 1
            if np.array_equal(new, mn[cells]):
                self._same += 1
                continue
            lr = self.log_ratio(mn, cells, new, rays)
            a = float(torch.rand((), dtype=torch.float64))
            if lr >= 0 or (lr > -math.inf and a < math.exp(lr)):
                mn[cells] = new
                self._accepted += 1
                moved += 1
        return moved

    @property
    def acceptance_rate(self) -> float:
        """Accepted share of the guide's proposals that differed from the current block."""
        return self._accepted / max(self._proposed - self._same, 1)

    def logging(self):
        return OrderedDict([("sweeps", self.sweeps), ("guide accept", f"{self.acceptance_rate:.3f}")])

    def diagnostics(self):
        return {
            "sweeps": self.sweeps,
            "guide_sweeps": self.guide_sweeps,
            "proposed": self._proposed,
            "unchanged_proposals": self._same,
            "accepted": self._accepted,
            "acceptance_rate": self.acceptance_rate,
        }

    # ------------------------------------------------------------------ checkpoints
    def _extra_state(self) -> dict[str, np.ndarray]:
        d = {f"base.{k}": v for k, v in self.base.state_dict().items()}
        d["guide_sweeps"] = np.asarray(self.guide_sweeps, np.int64)
        d["guide_counts"] = np.array([self._proposed, self._same, self._accepted], np.int64)
        return d

    def _load_extra_state(self, state) -> None:
        counts = np.asarray(state["guide_counts"]) if "guide_counts" in state else None
        if counts is None or counts.shape != (3,) or counts.dtype.kind not in "iu" or (counts < 0).any():
            raise KernelStateError("GuidedGibbs state 'guide_counts' must be 3 non-negative integers")
        sweeps = np.asarray(state.get("guide_sweeps", -1))
        if sweeps.shape != () or sweeps.dtype.kind not in "iu" or int(sweeps) < 0:
            raise KernelStateError("GuidedGibbs state 'guide_sweeps' must be a non-negative integer")
        self.base.load_state_dict({k[5:]: v for k, v in state.items() if k.startswith("base.")})
        self.guide_sweeps = int(sweeps)
        self._proposed, self._same, self._accepted = (int(v) for v in counts)
