r"""Learning a net field (:class:`~ogm_ppl.priors.NetFieldPrior`) in torch: maximum pseudo-likelihood, then
persistent contrastive divergence with the compiled Gibbs sampler's negative chains.

**Pseudo-likelihood** (Besag). ``max_theta 1/N sum_k log p(m_k | m_-k; theta) - lambda_/2 |theta|^2`` over the
training cells whose ``S x S`` neighbourhood (``S = 2w - 1``, every cell of the ``w^2`` windows holding the cell)
lies in the grid and in known cells. The conditional is exact: with ``nb`` the neighbourhood (``N x S^2``), the
``w^2`` windows' inputs are ``nb[:, idx]`` (``N x w^2 x w^2``, :func:`window_index`), their pre-activations one
matrix product with the ``w^2 x U`` unit weights, ``base = pre - y W[:, pos]`` the cell cleared, and

    l = a + sum_{windows, units} v_u (sigma(base + W_u[pos]) - sigma(base)),
    -log p(y | rest) = softplus(-(2y - 1) l).

Minibatches of ``N`` cells are drawn uniformly from all eligible training cells (:class:`CellBatches`); Adam.

**Persistent contrastive divergence** (Tieleman 2008). ``grad log p(m) = grad log p~(m) - E_theta[grad log p~]``:
per step the data term on ``B`` crops of training maps (``size x size``, wholly in known cells) and the model
term on ``B`` persistent chains of the same size, carried from step to step and moved by ``sweeps`` compiled
single-cell Gibbs sweeps under the current parameters
(:func:`~ogm_ppl.priors.compiled.net_field_patches.net_prior_sweeps`); the loss
``(mean_chains log p~ - mean_data log p~) / size^2`` has that gradient (per cell). Crops and chains alike are
scored as grids of their own (windows past their edge read ``pad``).

**Prior samples** (:func:`prior_sample_statistics`): whether a field's chains leave their start (an ordered
field's freeze where they begin), and how their maps compare with plans (:func:`sample_statistics`: occupied
share, mean runs of occupied and of free cells along rows and columns).

**Held-out score** (:func:`heldout_nll`): the mean ``-log p(m_k | m_-k)`` over the validation maps' eligible
cells, by the compiled conditionals of the bundle in float64
(:func:`~ogm_ppl.priors.compiled.sampling.conditional_nll`), so any compiled prior (a pattern field too) is scored on
the same cells.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import torch

from ogm_ppl.priors.compiled.net_field import ACTIVATIONS
from ogm_ppl.priors.compiled.net_field_patches import net_prior_sweeps
from ogm_ppl.priors.compiled.sampling import conditional_nll, prior_gibbs_sweeps
from ogm_ppl.priors.net_field import NetFieldPrior, activation_fn, energy, oriented

__all__ = [
    "CellBatches",
    "NetModel",
    "SAMPLE_STARTS",
    "data_crops_known",
    "describe_statistics",
    "eligible_cells",
    "heldout_nll",
    "pcd_loss",
    "pcd_update",
    "pl_loss",
    "prior_sample_statistics",
    "sample_statistics",
    "window_index",
]

#: the starts of :func:`prior_sample_statistics`' chains
SAMPLE_STARTS = ("free", "occupied")


def window_index(w: int) -> tuple[np.ndarray, np.ndarray]:
    """``(idx, pos)`` for a cell's ``S x S`` neighbourhood (``S = 2w - 1``, row-major, the cell at its centre):
    ``idx[q, p]`` the neighbourhood position of cell ``p`` of the ``q``-th window holding the centre (window
    anchored ``q // w, q % w`` from the neighbourhood's corner), ``pos[q]`` the centre's position in that window."""
    S, h = 2 * w - 1, w - 1
    q = np.arange(w * w)
    p = np.arange(w * w)
    idx = (q[:, None] // w + p[None, :] // w) * S + (q[:, None] % w + p[None, :] % w)
    pos = (h - q // w) * w + (h - q % w)
    return idx, pos


def eligible_cells(known: np.ndarray, w: int) -> np.ndarray:
    """Flat ids of the cells of a 2D grid whose ``(2w - 1)^2`` neighbourhood lies in the grid and in known cells."""
    kn = np.asarray(known, bool)
    R, C = kn.shape
    h = w - 1
    if R <= 2 * h or C <= 2 * h:
        return np.zeros(0, np.int64)
    bad = np.zeros((R + 1, C + 1), np.int64)
    bad[1:, 1:] = np.cumsum(np.cumsum(~kn, 0), 1)
    S = 2 * h + 1
    box = bad[S:, S:] - bad[:-S, S:] - bad[S:, :-S] + bad[:-S, :-S]  # (R - 2h) x (C - 2h): unknown in each box
    r, c = np.nonzero(box == 0)
    return ((r + h) * C + (c + h)).astype(np.int64)


class CellBatches:
    """Training cells for pseudo-likelihood: every eligible cell (:func:`eligible_cells`) of the maps
    (``(occupancy, known)`` pairs), drawn uniformly in minibatches of their neighbourhoods (:meth:`draw`)."""

    def __init__(self, maps: Sequence[tuple[np.ndarray, np.ndarray]], w: int) -> None:
        self.w = int(w)
        h = self.w - 1
        self.grids, self.cells, self.offsets = [], [], []
        for occ, known in maps:
            g = np.ascontiguousarray((np.asarray(occ, bool) & np.asarray(known, bool)).ravel(), np.uint8)
            cells = eligible_cells(known, self.w)
            if len(cells):
                C = np.asarray(occ).shape[1]
                d = np.arange(-h, h + 1)
                self.grids.append(g)
                self.cells.append(cells)
                self.offsets.append((d[:, None] * C + d[None, :]).ravel())
        self.counts = np.array([len(c) for c in self.cells], np.int64)
        self.n_cells = int(self.counts.sum())

    def draw(self, n: int, rng: np.random.Generator) -> tuple[torch.Tensor, torch.Tensor]:
        """``(nb, y)``: ``n`` cells drawn uniformly (with replacement), their neighbourhoods ``n x S^2`` and values
        ``n`` (float64); ``n >= n_cells`` gives every cell once, in order."""
        if self.n_cells == 0:
            raise ValueError("no training cell has its whole neighbourhood known")
        if n >= self.n_cells:
            parts = [g[c[:, None] + o[None, :]] for g, c, o in zip(self.grids, self.cells, self.offsets)]
        else:
            which = np.sort(rng.choice(len(self.counts), n, p=self.counts / self.n_cells))
            parts = []
            for i, cnt in zip(*np.unique(which, return_counts=True)):
                c = self.cells[i][rng.integers(0, self.counts[i], cnt)]
                parts.append(self.grids[i][c[:, None] + self.offsets[i][None, :]])
        nb = torch.from_numpy(np.concatenate(parts).astype(np.float64))
        return nb, nb[:, nb.shape[1] // 2].clone()


class NetModel(torch.nn.Module):
    """The trainable parameters of a net field (float64): ``filters`` ``H x w x w``, ``bias`` and ``out`` ``H``,
    ``unary``; ``pad`` and ``activation`` fixed. Initialised from ``seed``: filters ``N(0, 1/w^2)``, biases
    ``N(0, 0.1^2)``, output weights ``N(0, 0.05^2)`` (a weak field), the unary bias ``unary``."""

    def __init__(
        self, w: int = 5, hidden: int = 4, activation: str = "relu", pad: float = 0.5, seed: int = 0, unary=0.0
    ) -> None:
        super().__init__()
        if activation not in ACTIVATIONS:
            raise ValueError(f"activation must be one of {ACTIVATIONS}, got {activation!r}")
        g = torch.Generator().manual_seed(int(seed))
        f64 = torch.float64
        self.w, self.hidden, self.activation, self.pad = int(w), int(hidden), activation, float(pad)
        self.filters = torch.nn.Parameter(torch.randn(hidden, w, w, generator=g, dtype=f64) / w)
        self.bias = torch.nn.Parameter(0.1 * torch.randn(hidden, generator=g, dtype=f64))
        self.out = torch.nn.Parameter(0.05 * torch.randn(hidden, generator=g, dtype=f64))
        self.unary = torch.nn.Parameter(torch.tensor(float(unary), dtype=f64))
        self._idx, self._pos = (torch.from_numpy(a) for a in window_index(self.w))

    def arrays(self) -> dict[str, np.ndarray]:
        """The parameters as numpy float64 copies (``filters``, ``bias``, ``out``, ``unary``)."""
        return {k: v.detach().numpy().copy() for k, v in self.named_parameters()}

    def load_arrays(self, arrays: dict) -> NetModel:
        """Set the parameters from :meth:`arrays`' dict (shapes checked)."""
        with torch.no_grad():
            for k, v in self.named_parameters():
                a = torch.as_tensor(np.asarray(arrays[k], np.float64))
                if a.shape != v.shape:
                    raise ValueError(f"{k}: shape {tuple(a.shape)}, expected {tuple(v.shape)}")
                v.copy_(a)
        return self

    def prior(self, shape, occupancy: float | None = None) -> NetFieldPrior:
        """The :class:`~ogm_ppl.priors.NetFieldPrior` of the current parameters over ``shape``."""
        a = self.arrays()
        return NetFieldPrior(
            shape, a["filters"], a["bias"], a["out"], float(a["unary"]), self.pad, self.activation, occupancy
        )

    def log_odds(self, nb: torch.Tensor, y: torch.Tensor) -> torch.Tensor:
        """The exact conditional log-odds of the centres of ``N x S^2`` neighbourhoods with values ``y`` (module
        docstring): ``N``."""
        ww = self.w * self.w
        units = oriented(self.filters).reshape(-1, ww).T  # w^2 x U
        pre = nb[:, self._idx] @ units + self.bias.repeat_interleave(8)  # N x w^2 (windows) x U
        col = units[self._pos]  # w^2 x U: the centre's weights in each window
        base = pre - y[:, None, None] * col
        act = activation_fn(self.activation)
        v = self.out.repeat_interleave(8)
        return self.unary + ((act(base + col) - act(base)) * v).sum((1, 2))

    def energy(self, x: torch.Tensor) -> torch.Tensor:
        """``log p~`` of ``B x R x C`` maps (:func:`~ogm_ppl.priors.net_field.energy`)."""
        return energy(x, self.filters, self.bias, self.out, self.unary, self.pad, self.activation)

    def penalty(self) -> torch.Tensor:
        """``|theta|^2 / 2`` over the filters, biases and output weights (not the unary bias)."""
        return 0.5 * sum((p**2).sum() for n, p in self.named_parameters() if n != "unary")  # type: ignore[return-value]


def pl_loss(model: NetModel, nb: torch.Tensor, y: torch.Tensor) -> torch.Tensor:
    """Mean ``-log p(y | neighbourhood)`` of a batch (:meth:`NetModel.log_odds`)."""
    lo = model.log_odds(nb, y)
    return torch.nn.functional.softplus(-(2 * y - 1) * lo).mean()


def pcd_loss(model: NetModel, data: torch.Tensor, chains: torch.Tensor) -> torch.Tensor:
    """``(mean log p~(chains) - mean log p~(data)) / cells`` of ``B x R x C`` batches: its gradient is minus the
    PCD estimate of the log-likelihood's gradient per cell."""
    cells = data.shape[-1] * data.shape[-2]
    return (model.energy(chains).mean() - model.energy(data).mean()) / cells


def pcd_update(
    model: NetModel, opt, data: np.ndarray, chains: np.ndarray, sweeps: int, seed: int, lambda_: float = 0.0
) -> float:
    """One step of persistent contrastive divergence (maximum likelihood with a Markov-chain negative phase):
    ``sweeps`` compiled Gibbs sweeps of the ``B x S^2`` uint8 ``chains`` under the current field (in place), then
    one step of the optimiser ``opt`` on :func:`pcd_loss` of the ``B' x S^2`` uint8 ``data`` against them, plus
    ``lambda_`` times :meth:`NetModel.penalty`. Returns the loss before the step."""
    size = math.isqrt(chains.shape[1])
    if size * size != chains.shape[1] or data.shape[1] != chains.shape[1]:
        raise ValueError(f"chains and data must be square grids of one size, got {chains.shape} and {data.shape}")
    advance_chains(model, chains, size, sweeps, seed)
    grid = (-1, size, size)
    x = torch.from_numpy(data.reshape(grid).astype(np.float64))
    loss = pcd_loss(model, x, torch.from_numpy(chains.reshape(grid).astype(np.float64)))
    opt.zero_grad()
    (loss + lambda_ * model.penalty()).backward()
    opt.step()
    return float(loss.detach())


def advance_chains(model: NetModel, chains: np.ndarray, size: int, sweeps: int, seed: int) -> None:
    """``sweeps`` compiled Gibbs sweeps of the ``B x size^2`` uint8 chains under the model's current field."""
    net_prior_sweeps(model.prior((size, size)).compiled(), chains, int(sweeps), int(seed))


def data_crops_known(
    maps: Sequence[tuple[np.ndarray, np.ndarray]], n: int, size: int, rng: np.random.Generator, tries: int = 50
) -> np.ndarray:
    """``n x size^2`` uint8 crops of the maps at random maps and offsets (uniform over the maps' areas), each wholly
    in known cells where one of ``tries`` draws finds such a crop (else unknown cells read as free)."""
    big = [(o, k) for o, k in maps if o.shape[0] >= size and o.shape[1] >= size]
    if not big:
        raise ValueError(f"no training map is at least {size} x {size} cells")
    area = np.array([(o.shape[0] - size + 1) * (o.shape[1] - size + 1) for o, _ in big], np.float64)
    out = np.empty((n, size * size), np.uint8)
    for b in range(n):
        for _ in range(tries):
            o, k = big[int(rng.choice(len(big), p=area / area.sum()))]
            r = int(rng.integers(o.shape[0] - size + 1))
            c = int(rng.integers(o.shape[1] - size + 1))
            if k[r : r + size, c : c + size].all():
                break
        out[b] = (o & k)[r : r + size, c : c + size].ravel()
    return out


def heldout_nll(prior_for_shape, maps: Sequence[tuple[np.ndarray, np.ndarray]], w: int) -> tuple[float, int]:
    """``(mean -log p(m_k | m_-k), cells)`` over the cells of ``maps`` whose ``(2w - 1)^2`` neighbourhood lies in
    the grid and in known cells, by the compiled conditionals of ``prior_for_shape(shape)`` (a compiled prior's
    bundle, e.g. ``lambda s: model.prior(s).compiled()``), float64."""
    tot, n = 0.0, 0
    for occ, known in maps:
        cells = eligible_cells(known, w)
        if not len(cells):
            continue
        m = np.ascontiguousarray((np.asarray(occ, bool) & np.asarray(known, bool)).ravel(), np.uint8)
        tot += conditional_nll(prior_for_shape(np.asarray(occ).shape), m, cells)
        n += len(cells)
    return (tot / n if n else float("nan")), n


def sample_statistics(maps: np.ndarray) -> dict[str, float]:
    """Statistics of ``B x R x C`` binary maps, pooled: ``occupied`` the occupied share, ``occupied_run`` and
    ``free_run`` the mean length of the maximal runs of occupied and of free cells along rows and along columns
    (a run cut by the map's edge counts as it is; ``nan`` when there is none). A plan's walls give occupied runs of
    their thickness across and their length along; noise of share ``p`` gives ``1 / (1 - p)``."""
    x = np.asarray(maps, bool)
    if x.ndim != 3 or x.size == 0:
        raise ValueError(f"maps must be a non-empty B x R x C array, got shape {x.shape}")
    out = {"occupied": float(x.mean())}
    for key, v in (("occupied_run", True), ("free_run", False)):
        cells = runs = 0
        for a in (x, x.transpose(0, 2, 1)):
            b = (a == v).reshape(-1, a.shape[-1]).astype(np.int8)
            cells += int(b.sum())
            runs += int((np.diff(b, axis=1, prepend=0) == 1).sum())
        out[key] = cells / runs if runs else float("nan")
    return out


def prior_sample_statistics(prior, chains: int = 2, sweeps: int = 100, edge: int = 8, seed: int = 0) -> dict:
    """:func:`sample_statistics` of a compiled prior's samples on its 2D grid: ``chains`` chains from each start of
    :data:`SAMPLE_STARTS` (all free, all occupied), ``sweeps`` compiled single-cell Gibbs sweeps on the prior
    alone, the cells at least ``edge`` from the grid's edges read at the end. Returns ``{start: statistics}`` and
    ``start_gap``, the difference of the two starts' occupied shares (near 1: chains frozen at their start, an
    ordered phase; near 0: they forget it)."""
    R, C = prior.shape if len(prior.shape) == 2 else (1, prior.shape[0])
    if R <= 2 * edge or C <= 2 * edge:
        raise ValueError(f"a {R} x {C} grid has no cell {edge} from its edges")
    bundle = prior.compiled()
    out: dict = {}
    for start in SAMPLE_STARTS:
        maps = np.full((int(chains), R * C), start == "occupied", np.uint8)
        prior_gibbs_sweeps(bundle, maps, int(sweeps), int(seed))
        out[start] = sample_statistics(maps.reshape(-1, R, C)[:, edge:-edge, edge:-edge])
    out["start_gap"] = out["occupied"]["occupied"] - out["free"]["occupied"]
    return out


def describe_statistics(row: dict) -> str:
    """One line of :func:`prior_sample_statistics`' result."""
    parts = [
        f"{k}: occupied {row[k]['occupied']:.3f}, runs {row[k]['occupied_run']:.1f} / {row[k]['free_run']:.1f}"
        for k in SAMPLE_STARTS
    ]
    return "; ".join(parts) + f" (start gap {row['start_gap']:.3f})"
